//! The twin's workflows over the co-simulation layer: calibration, training the GP corrector,
//! active learning, diagnosis and control.

pub mod calibrate;
pub mod control;
pub mod diagnose;
pub mod learn;
pub mod train;
