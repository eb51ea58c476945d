//! Zero-time blocks of the master: functions of their inputs evaluated at each communication
//! point: the LQR controller and the active-learning supervisor.

pub mod lqr;
pub mod supervisor;
