//! Zero-time blocks of the master: functions of their inputs evaluated at each communication
//! point: the LQR controller and the active-learning supervisor (the hybrid test's actuator and
//! interface blocks live with their workflow, `workflows/hybrid/blocks.rs`).

pub mod lqr;
pub mod supervisor;
