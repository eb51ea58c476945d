//! `fmu_lqr`: the shear frame's LQR controller as an FMI 2.0 co-simulation FMU.
//!
//! The law is `numerics::lqr::Controller`, the code the orchestrator's `LqrBlock` runs: the
//! state `[y; ẏ]` is estimated from the measured floor accelerations (integration with drift
//! removal, or a steady-state Kalman observer on the model given by `m1..k3`), and the command is
//! `f_c = K ŵ`.
//!
//! One sample per communication step, at `sample_interval`: `fmi2DoStep(t, h)` reads the inputs
//! set before it (`acc1..3`, `force`: the sample at `t`), runs `Controller::step` and leaves the
//! new command in `control_force`. The output has no direct feedthrough; a master carries it to
//! the structure for the next step, so the command computed from the sample at `t_k` acts over
//! `[t_{k+1}, t_{k+2}]` — the controller's one sample of computation delay. A step other than
//! `sample_interval` (1e-9 relative) is refused with `fmi2Error` and a logged message, and the
//! instance carries on.

pub mod model;
pub mod variables;

pub use model::LqrModel;

fmi2::export_fmu!(crate::model::LqrModel);
