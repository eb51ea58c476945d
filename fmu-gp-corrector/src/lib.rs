//! `fmu_gp_corrector`: the data-based component of the twin as an FMI 2.0 co-simulation FMU.
//!
//! One independent zero-mean GP per measured channel (Matérn 3/2 ARD kernel, Gaussian noise,
//! `numerics::gp`) maps lags of the physics predictions and the excitation ([`lags`]) to a
//! correction of that channel, in its own quantity. The channels and the excitation are the
//! corrector's layout ([`layout`]): the paper's rig (acc1..3 and the force, three GPs on all
//! four columns) by default, any set of `acc<i>`, `vel<i>`, `disp<i>` under `force` or
//! `ground_acc` when the bundled training file names them, each GP then on its own channel, at
//! most two nearest measured neighbours and the excitation. What is said below of "floors" and
//! "accelerations" is the rig's case:
//!
//! - `target` = 0 (default, discrepancy): the GP models measured − physics; the corrected
//!   acceleration is physics + GP mean;
//! - `target` = 1 (the reference paper's form): the GP models the measured acceleration itself;
//!   the corrected acceleration is the GP mean.
//!
//! Outputs per floor: the corrected acceleration, the latent variance `V(f*)` (what active
//! learning thresholds) and the predictive standard deviation `√(V(f*) + σ_n²)`, computed when
//! read from the inputs set since the last step (direct feedthrough) and the lag buffer.
//!
//! Training data come from a JSON training file ([`training`]): `training_path`, or the FMU's
//! `resources/training.json`; without either the GPs have no data, the corrected acceleration is
//! the physics one (discrepancy form) and the latent variance the prior signal variance. With
//! `learn` true, each `fmi2DoStep` adds the current sample to every floor's GP (`O(n²)`), and the
//! hyperparameters are refitted every `refit_every` learned points. The FMU state (get, set,
//! serialize) carries the training sets, the hyperparameters and the lag buffer.
//!
//! One sample per communication step: the lag buffer holds samples, not times, so the master
//! should step at the sampling interval of the training data (1/51.2 s for the example records).
//! Before `lags` steps have been taken, the missing lags are the first sample seen.
//!
//! Call order (the FMI's): instantiate (reads and checks `resources/training.json`) → set
//! parameters → exit initialization (builds the GPs: reads `training_path`, checks it against
//! `lags` and `target`, fits hyperparameters the file does not give) → per step: set inputs →
//! read outputs → do step (learn, refit, advance the lag buffer).

pub mod lags;
pub mod layout;
pub mod model;
pub mod training;
pub mod variables;

pub use lags::{input_dimension, lagged_inputs, LagBuffer, Sample};
pub use layout::Layout;
pub use model::{
    per_channel, FloorGp, Floors, GpCorrector, Settings, DEFAULT_LAGS, DEFAULT_REFIT_EVERY,
};
pub use training::{FloorHyperparameters, LayoutTraining, TargetForm, TrainingFile};

/// What can go wrong with the corrector's training data.
#[derive(Debug, thiserror::Error)]
pub enum CorrectorError {
    /// A training file that cannot be read, parsed or used; `path` names it.
    #[error("training file {path}: {problem}")]
    TrainingFile { path: String, problem: String },
    #[error(transparent)]
    Gp(#[from] numerics::gp::GpError),
}

fmi2::export_fmu!(crate::model::GpCorrector);
