//! `fmu_substructure`: a substructure of the simulated real-time hybrid test as an FMI 2.0
//! co-simulation FMU. The equations and the RK4 are `numerics::substructure`, the code the
//! orchestrator's Rust loop (`workflows::hybrid::run`) runs.
//!
//! One FMU, three roles, chosen by the Integer parameter `role`; the variables are the union of
//! the roles'. A role ignores the other roles' inputs, and their outputs read 0.
//!
//! * `role = 0`, **numerical**: floors 1 and 2 with storeys 1 and 2 (`m1 m2 c1 c2 k1 k2`).
//!   Inputs `force` (the excitation on floor 1; first-order input interpolation, as the shear
//!   FMU's `force`), `interface_force` (floor 2's load, acting as `−interface_force` on floor
//!   2) and `interface_force_rate` (its slope over the coming step: `load(τ) = interface_force +
//!   interface_force_rate·τ`). Outputs `y1 v1 y2 v2`, the state at the communication point (no
//!   direct feedthrough). `fmi2DoStep(t, h)` takes `substeps` RK4 steps of `h / substeps`.
//!   Facing role 1 the load is the measured force `F_m`. Facing role 2, whose specimen holds
//!   floor 2, floor 2 here is the twin's model of it kept as a predictor, and the master loads
//!   it with `F_m` less its own inertia (`numerics::substructure::interface_load`): the numerical
//!   substructure is then floor 1 and storey 2's interface equation, the paper's eqs (13)–(14).
//! * `role = 1`, **physical, specimen floor 3**: storey 3 with the one-sided bumper between
//!   floors 2 and 3, and floor 3 (`m3 c3 k3 gap contact_stiffness`), moved at floor 2 by the
//!   actuator. `role = 2`, **physical, specimen floors 2 and 3** (the paper's split): the same
//!   with floor 2's mass `m2`, which the actuator accelerates. Inputs
//!   `y2_start v2_start y2_end v2_end`: the motion the actuator imposes over one control step of
//!   `control_step` s, the cubic Hermite through `(y2_start, v2_start)` and `(y2_end, v2_end)`.
//!   Outputs `measured_force` (`F_m = c3 (ẏ2 − ẏ3) + k3 (y2 − y3) + k_nl·max(0, y2 − y3 − gap)`,
//!   plus `m2 ÿ2` in role 2), `y3`, `v3`, `relative` (`y2 − y3`), `a2` (`ÿ2`, the Hermite's):
//!   the specimen at the *end* of that motion. They are a
//!   direct feedthrough of the four inputs (the FMU integrates the motion, `substeps` RK4 steps,
//!   when they are read), and `fmi2DoStep(t, h)` keeps that end state as the start of the next
//!   motion (`h` must be `control_step`, 1e-9 relative). So within one communication point a
//!   master can take the numerical side's new floor 2, turn it into the actuator's motion, and
//!   read the force that motion produces before the numerical side steps again: the staggered
//!   coupling of a real-time hybrid test, in which the numerical side steps with the force
//!   measured at the end of the last actuator motion.
//!
//! Parameters are checked when initialization ends: a non-positive mass, a negative gap, a
//! negative damping or stiffness, a non-positive `control_step` or `substeps`, or a `role` other
//! than 0, 1 or 2 are refused with an error naming the variable. A panic never crosses the C boundary
//! (the `fmi2` export layer catches it).

pub mod model;
pub mod variables;

pub use model::SubstructureModel;

fmi2::export_fmu!(crate::model::SubstructureModel);
