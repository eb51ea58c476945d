//! Zero-time blocks of the master: functions of their inputs evaluated at each communication
//! point: the LQR controller, the active-learning supervisor and the hybrid test's actuator
//! and interface.

pub mod actuator;
pub mod lqr;
pub mod supervisor;
