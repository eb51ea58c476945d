//! `fmu_lqr`: the shear frame's LQR controller as an FMI 2.0 co-simulation FMU, for any shear
//! building.
//!
//! The law is `numerics::lqr::Controller`, the code the orchestrator's `LqrBlock` runs: the
//! state `[y; ẏ]` is estimated from the measured channels (integration of every floor's
//! acceleration with drift removal, or a steady-state Kalman observer on the model given by
//! `m1..kN` reading any observable set of `acc<i>`, `vel<i>`, `disp<i>`), and the command is
//! `f_c = K ŵ`, a force on the actuator's floor.
//!
//! One library serves every layout (storeys, excitation, actuator floor, measured channels): it
//! reads `resources/structure.json` at `fmi2Instantiate` ([`variables::Layout`]) and serves that
//! layout's variable table; without the resource, the paper's rig (three storeys, the shaker and
//! the actuator on floor 1, acc1..acc3).
//!
//! One sample per communication step, at `sample_interval`: `fmi2DoStep(t, h)` reads the inputs
//! set before it (the measured channels and the excitation, `force` or `ground_acc`: the
//! sample at `t`), runs `Controller::step` and leaves the
//! new command in `control_force`. The output has no direct feedthrough; a master carries it to
//! the structure for the next step, so the command computed from the sample at `t_k` acts over
//! `[t_{k+1}, t_{k+2}]` — the controller's one sample of computation delay. A step other than
//! `sample_interval` (1e-9 relative) is refused with `fmi2Error` and a logged message, and the
//! instance carries on.

pub mod model;
pub mod variables;

pub use model::LqrModel;

fmi2::export_fmu!(crate::model::LqrModel);
