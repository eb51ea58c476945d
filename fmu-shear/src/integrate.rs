//! How `ShearModel::advance` integrates one communication step, always as RK4 with `substeps`
//! sub-steps, in one of two ways:
//!
//! - **No effect enabled** (the linear model, any number of storeys): RK4 applied to a linear
//!   system with inputs that are linear in time is itself an affine map of the state and of the
//!   inputs' values and slopes (`crate::linear::LinearStepMap`: a 2N-square matrix and four
//!   columns), computed once per (parameters, step size), then each step is one matrix–vector
//!   product. Equal to stepping RK4 directly up to rounding (the tests check 1e-12).
//! - **Effects enabled**: RK4 sub-steps, split where a contact gap opens or closes. The contact
//!   force has a kink there, and an RK4 step across a kink loses its order (errors of tens of
//!   percent with frequent contact at 8 sub-steps); splitting the step at the crossing, located
//!   by regula falsi on the switch function, restores it.

use numerics::ode::{self, OdeState};

use crate::effects::Switches;
use crate::linear::StepInputs;
use crate::model::{ShearModel, ADAPTIVE_TOLERANCE};
use crate::piecewise_any::{AnyContactMaps, Buffer};

/// The state `[y, ẏ]` of the paper's three storeys as a fixed array (the effect paths of the
/// paper's rig; any other structure steps a small vector of length 2N).
pub type State = [f64; 6];

/// `ẋ` for the state `x = [y, ẏ]` (any N) under the excitation `excitation` and the control
/// force `control`.
#[inline]
pub fn rhs<S: OdeState>(model: &ShearModel, x: &S, excitation: f64, control: f64) -> S {
    let xs = x.as_ref();
    let n = xs.len() / 2;
    let mut out = x.clone();
    let o = out.as_mut();
    o[..n].copy_from_slice(&xs[n..]);
    model.accelerations_into(&xs[..n], &xs[n..], excitation, control, &mut o[n..]);
    out
}

/// `ẋ` at `tau` into the step: the inputs' ramps evaluated there.
#[inline]
fn rhs_at<S: OdeState>(model: &ShearModel, x: &S, inputs: &StepInputs, tau: f64) -> S {
    rhs(
        model,
        x,
        inputs.excitation + inputs.excitation_slope * tau,
        inputs.control + inputs.control_slope * tau,
    )
}

/// The switch values of the effects at the state `x = [y, ẏ]`.
#[inline]
fn switches<S: OdeState>(model: &ShearModel, x: &S) -> Switches {
    let xs = x.as_ref();
    model.effects.switches(&xs[..xs.len() / 2])
}

/// The switch values as numerics' stepper reads them.
impl AsRef<[f64]> for Switches {
    fn as_ref(&self) -> &[f64] {
        &self.values
    }
}

/// The exact contact flows (`piecewise_any`) of the model's contacts over one step from `x0`,
/// the maps built or adapted for its parameters and step first; `None` when the exact path does
/// not serve the model (too many contacts) or a flow is not finite.
pub fn exact_contacts<B: Buffer>(
    model: &mut ShearModel,
    x0: &B,
    inputs: &StepInputs,
    h: f64,
) -> Option<B> {
    if !AnyContactMaps::serves(model) {
        return None;
    }
    if !model
        .contact_maps
        .as_ref()
        .is_some_and(|m| m.fits(model, h))
    {
        let maps = match model.contact_maps.take() {
            Some(mut maps) => {
                maps.adapt(model, h);
                maps
            }
            None => Box::new(AnyContactMaps::new(model, h)),
        };
        model.contact_maps = Some(maps);
    }
    model.contact_maps.as_mut()?.advance_in(x0, inputs).ok()
}

/// RK4 sub-steps over `[0, h]` from `x`, split at every switch of the effects (contact kinks):
/// [`numerics::ode::rk4_with_events`] on the model's right-hand side.
pub fn rk4_with_events<S: OdeState>(
    model: &ShearModel,
    x: &S,
    inputs: &StepInputs,
    h: f64,
    substeps: u32,
) -> S {
    // Without a kink (cubic stiffness, friction) the switches are empty at every sub-step:
    // not asked for (a tenth of a smooth effect's step went to building them), the same steps.
    let switching = model.effects.any_switching();
    ode::rk4_with_events(
        |tau, x: &S| rhs_at(model, x, inputs, tau),
        |x: &S| {
            if switching {
                switches(model, x)
            } else {
                Switches::default()
            }
        },
        x,
        h,
        substeps,
    )
}

/// Error-controlled Dormand–Prince 5(4) over `[0, h]` from `x` to [`ADAPTIVE_TOLERANCE`], split
/// at every switch of the effects: [`numerics::ode::dopri5_with_events`] on the model's
/// right-hand side. `step` carries the trial step from one call to the next.
pub fn dopri5_with_events<S: OdeState>(
    model: &ShearModel,
    x: &S,
    inputs: &StepInputs,
    h: f64,
    step: &mut f64,
) -> S {
    let n = x.as_ref().len() / 2;
    // Displacements and velocities each against the largest of their kind over the step.
    let error_norm = |error: &S, a: &S, b: &S| -> f64 {
        let (error, a, b) = (error.as_ref(), a.as_ref(), b.as_ref());
        let largest = |range: std::ops::Range<usize>| {
            range
                .map(|i| a[i].abs().max(b[i].abs()))
                .fold(f64::MIN_POSITIVE, f64::max)
        };
        let (sy, sv) = (largest(0..n), largest(n..2 * n));
        let worst_y = error[..n].iter().fold(0.0f64, |m, e| m.max(e.abs())) / sy;
        let worst_v = error[n..].iter().fold(0.0f64, |m, e| m.max(e.abs())) / sv;
        worst_y.max(worst_v) / ADAPTIVE_TOLERANCE
    };
    let mut control = ode::Adaptive {
        error_norm,
        step: *step,
    };
    let x = ode::dopri5_with_events(
        |tau, x: &S| rhs_at(model, x, inputs, tau),
        |x: &S| switches(model, x),
        x,
        h,
        &mut control,
    );
    *step = control.step;
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::Effects;
    use crate::linear::{LinearStepMap, StepInputs};
    use crate::model::ShearParameters;
    use numerics::ode::rk4_substeps;

    /// The affine step map is the RK4 sub-steps themselves, rearranged: over a long random-ish
    /// run the two agree to rounding (bound 1e-12 of the peak).
    #[test]
    fn the_linear_step_map_equals_stepping_rk4_directly() {
        let mut params = ShearParameters::default();
        params.mass = vec![4.6, 5.3, 4.9];
        params.damping = vec![8.1, 3.7, 2.6];
        params.stiffness = vec![3850.0, 4100.0, 4680.0];
        params.substeps = 16;
        let model = ShearModel::new(params.clone(), Effects::default());
        let h = 1.0 / 51.2;
        let map = LinearStepMap::new(&params, h);
        let (mut a, mut b) = (vec![0.0; 6], [0.0; 6]);
        let mut peak = 0.0f64;
        let mut worst = 0.0f64;
        for k in 0..2000 {
            let u0 = (0.37 * k as f64).sin() + 0.5 * (1.3 * k as f64).cos();
            let u1 = (0.37 * (k + 1) as f64).sin() + 0.5 * (1.3 * (k + 1) as f64).cos();
            let slope = (u1 - u0) / h;
            a = map.apply(
                &a,
                &StepInputs {
                    excitation: u0,
                    excitation_slope: slope,
                    ..Default::default()
                },
            );
            b = rk4_substeps(
                |tau, x: &State| rhs(&model, x, u0 + slope * tau, 0.0),
                0.0,
                &b,
                h,
                16,
            );
            for i in 0..6 {
                peak = peak.max(b[i].abs());
                worst = worst.max((a[i] - b[i]).abs());
            }
        }
        assert!(peak > 1e-4, "the run moves: peak {peak:e}");
        assert!(
            worst <= 1e-12 * peak,
            "map vs direct RK4: {worst:e} of {peak:e}"
        );
    }

    /// Splitting at the gap keeps RK4's fourth order with contact: doubling the sub-steps cuts
    /// the error about 16× (measured 15.1× and 15.5× between 16, 32 and 64 sub-steps).
    #[test]
    fn steps_split_at_contact_converge_at_fourth_order() {
        let run = |substeps: u32| {
            let mut params = ShearParameters::default();
            params.damping = vec![1.0; 3];
            params.substeps = substeps;
            let mut effects = Effects::default();
            effects.contact.enable(2, true);
            effects.contact.effect_mut(2).gap = 2e-4;
            let model = ShearModel::new(params, effects);
            let h = 1.0 / 51.2;
            let mut x = [0.0; 6];
            for k in 0..400 {
                let u0 = 2.0 * (0.9 * k as f64).sin();
                let u1 = 2.0 * (0.9 * (k + 1) as f64).sin();
                let inputs = StepInputs {
                    excitation: u0,
                    excitation_slope: (u1 - u0) / h,
                    ..Default::default()
                };
                x = rk4_with_events(&model, &x, &inputs, h, substeps);
            }
            x
        };
        let reference = run(1024);
        let error = |n: u32| {
            let x = run(n);
            (0..6)
                .map(|i| (x[i] - reference[i]).abs())
                .fold(0.0, f64::max)
        };
        let (e16, e32, e64) = (error(16), error(32), error(64));
        println!(
            "errors: 16 {e16:e}, 32 {e32:e}, 64 {e64:e}; ratios {} {}",
            e16 / e32,
            e32 / e64
        );
        assert!(e16 > 0.0 && e32 > 0.0);
        for (coarse, fine) in [(e16, e32), (e32, e64)] {
            let ratio = coarse / fine;
            assert!(
                (10.0..25.0).contains(&ratio),
                "error ratio per doubling {ratio} (16: {e16:e}, 32: {e32:e}, 64: {e64:e})"
            );
        }
    }
}
