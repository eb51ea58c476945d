//! The twin's workflows over the co-simulation layer: calibration, training the GP corrector,
//! active learning and diagnosis.

pub mod calibrate;
pub mod diagnose;
pub mod learn;
pub mod train;
