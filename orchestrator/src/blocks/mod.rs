//! Zero-time blocks of the master: functions of their inputs evaluated at each communication
//! point (the active-learning supervisor; next, the LQR).

pub mod supervisor;
