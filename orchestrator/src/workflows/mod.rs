//! The twin's workflows over the co-simulation layer: calibration, training the GP corrector,
//! active learning, diagnosis, control and the simulated hybrid test.

pub mod calibrate;
pub mod control;
pub mod diagnose;
pub mod hybrid;
pub mod learn;
pub mod train;
pub mod watch;
