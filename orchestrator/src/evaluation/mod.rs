//! How well a model fits a record: statistics (NMSE, variance, the first sample after the
//! transient), the comparison of predictions with measurements (failing windows) and
//! frequency responses.

pub mod compare;
pub mod frf;
pub mod stats;
