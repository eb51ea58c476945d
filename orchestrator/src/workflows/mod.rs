//! The twin's workflows over the co-simulation layer: calibration, training the GP corrector,
//! active learning, diagnosis, control and the simulated hybrid test.

pub mod calibrate;
pub mod compare;
pub mod control;
pub mod diagnose;
pub mod hybrid;
pub mod init;
pub mod learn;
pub mod modal;
pub mod options;
pub mod train;
pub mod watch;
