//! How well a model fits a record: statistics (NMSE, variance, the first sample after the
//! transient) and the comparison of predictions with measurements (failing windows).

pub mod compare;
pub mod stats;
