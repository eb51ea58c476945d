//! The discovered terms in the model: a term that is a known force law gives that law's
//! response, through the FMU's own variables as a host sets them.

use fmi2::CoSimModel;
use fmu_shear::effects::discovered::{value_reference, Slot};
use fmu_shear::effects::{Effects, Function, Site, Term};
use fmu_shear::integrate::{rhs, State};
use fmu_shear::variables::info;
use fmu_shear::{Integrator, ShearModel, ShearParameters};
use numerics::ode::rk4_substeps;

mod common;

const STEP: f64 = 1.0 / 51.2;
const SUBSTEPS: u32 = 16;

fn params() -> ShearParameters {
    ShearParameters {
        mass: vec![5.0, 5.4, 4.9],
        damping: vec![0.05, 0.03, 0.04],
        stiffness: vec![4300.0, 3900.0, 4021.0],
        substeps: SUBSTEPS,
        ..Default::default()
    }
}

fn force(steps: usize) -> Vec<f64> {
    common::band_limited_force(steps, STEP)
}

/// The accelerations after each step, the model driven as a host drives it.
fn drive(model: &mut ShearModel, force: &[f64]) -> Vec<[f64; 3]> {
    (0..force.len() - 1)
        .map(|n| common::step_ramped(model, force, n, STEP))
        .collect()
}

/// max |a − b| over max |b|, all floors.
fn relative_difference(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    let peak = b.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    let worst = a
        .iter()
        .flatten()
        .zip(b.iter().flatten())
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    worst / peak
}

/// A model with `terms`, stepped by the fixed RK4 sub-steps (`integrator` = 1), so that the
/// laws are compared at the same sub-steps as the references here.
fn with_terms(params: ShearParameters, terms: &[Term]) -> ShearModel {
    let mut effects = Effects::default();
    effects.switch_on_terms(terms).expect("valid terms");
    let mut model = ShearModel::new(params, effects);
    model.integrator = Integrator::FixedSubsteps;
    model
}

/// Storey `x` with coefficient k is k more stiffness in that storey. Both runs go through the
/// effects path at the same sub-steps (the stiffer structure carries an enabled term of
/// coefficient 0), so they differ by rounding only. Measured ~1e-14 relative; bound 1e-9.
#[test]
fn a_storey_x_term_is_extra_storey_stiffness() {
    let f = force(1024);
    for storey in 1..=3 {
        let k_extra = 800.0;
        let mut with_term = with_terms(
            params(),
            &[Term::new(Function::X, Site::Storey(storey), k_extra)],
        );
        let mut stiffer_params = params();
        stiffer_params.stiffness[storey - 1] += k_extra;
        let mut stiffer = with_terms(
            stiffer_params,
            &[Term::new(Function::X3, Site::Floor(1), 0.0)],
        );
        let a = drive(&mut with_term, &f);
        let b = drive(&mut stiffer, &f);
        let difference = relative_difference(&a, &b);
        println!("storey {storey}: x term against k + {k_extra}: {difference:e}");
        assert!(difference < 1e-9, "storey {storey}: {difference:e}");
        // And it is not the unmodified structure.
        let plain = drive(&mut with_terms(params(), &[]), &f);
        assert!(relative_difference(&plain, &b) > 1e-2);
    }
}

/// Floor `v` with coefficient c is a viscous damper from that floor to the ground: the model
/// against RK4 at the same sub-steps on the modified linear equations (the linear model's
/// accelerations minus c·v/m on that floor). Measured ~1e-15 relative; bound 1e-9.
#[test]
fn a_floor_v_term_is_a_damper_to_the_ground() {
    let f = force(1024);
    let c = 2.0;
    for floor in 1..=3 {
        let mut model = with_terms(params(), &[Term::new(Function::V, Site::Floor(floor), c)]);
        let a = drive(&mut model, &f);

        let linear = ShearModel::new(params(), Effects::default());
        let m = params().mass[floor - 1];
        let rhs_damped = |x: &State, u: f64| -> State {
            let mut dx = rhs(&linear, x, u, 0.0);
            dx[3 + floor - 1] -= c * x[3 + floor - 1] / m;
            dx
        };
        let mut x = [0.0; 6];
        let mut b = Vec::new();
        for n in 0..f.len() - 1 {
            let slope = (f[n + 1] - f[n]) / STEP;
            x = rk4_substeps(
                |tau, x: &State| rhs_damped(x, f[n] + slope * tau),
                0.0,
                &x,
                STEP,
                SUBSTEPS,
            );
            let dx = rhs_damped(&x, f[n + 1]);
            b.push([dx[3], dx[4], dx[5]]);
        }
        let difference = relative_difference(&a, &b);
        println!("floor {floor}: v term against a damper to ground: {difference:e}");
        assert!(difference < 1e-9, "floor {floor}: {difference:e}");
    }
}

/// `max(0,x-s)` and `min(0,x+s)` with the same coefficient at a storey are the two-sided bumper
/// of `contact` with gap s, and the steps are split at the same kinks. Measured ~1e-15 relative
/// with a bumper closing often; bound 1e-9.
#[test]
fn the_two_ramps_at_a_storey_are_the_contact_bumper_split_at_the_same_kinks() {
    let f: Vec<f64> = force(1024).iter().map(|x| 3.0 * x).collect();
    let (gap, k_c) = (2e-4, 9000.0);
    let mut ramps = with_terms(
        params(),
        &[
            Term {
                scale: gap,
                ..Term::new(Function::RampUp, Site::Storey(3), k_c)
            },
            Term {
                scale: gap,
                ..Term::new(Function::RampDown, Site::Storey(3), k_c)
            },
        ],
    );
    let mut effects = Effects::default();
    effects.contact.enable(2, true);
    effects.contact.effect_mut(2).gap = gap;
    effects.contact.effect_mut(2).stiffness = k_c;
    let mut contact = ShearModel::new(params(), effects);
    contact.integrator = Integrator::FixedSubsteps;
    let switches = ramps.effects.switches(&[1e-3, 2e-3, 2.5e-3]);
    assert_eq!(switches.values.len(), 2, "one switch per ramp");
    let a = drive(&mut ramps, &f);
    let b = drive(&mut contact, &f);
    let difference = relative_difference(&a, &b);
    println!("ramps against contact: {difference:e}");
    assert!(difference < 1e-9, "{difference:e}");
    let plain = drive(&mut with_terms(params(), &[]), &f);
    assert!(
        relative_difference(&plain, &b) > 1e-2,
        "the bumper closes on this force"
    );
}

/// Terms set through the FMU's variables, as a host sets them, are the terms `switch_on_terms`
/// sets; the table has the variables at the documented value references.
#[test]
fn terms_set_through_the_variables_equal_switch_on_terms() {
    let terms = [
        Term::new(Function::VAbsV, Site::Floor(2), 40.0),
        Term::new(Function::X3, Site::Storey(3), 2e8),
        Term {
            scale: 5e-3,
            ..Term::new(Function::TanhV, Site::Floor(1), 0.05)
        },
    ];
    let mut by_api = with_terms(params(), &terms);
    let mut by_variables = ShearModel::new(params(), Effects::default());
    by_variables.integrator = Integrator::FixedSubsteps;
    for (i, term) in terms.iter().enumerate() {
        let index = i + 1;
        let enabled = format!("discovered{index}_enabled");
        let var = info().by_name(&enabled).expect("enabled variable");
        assert_eq!(var.vr, value_reference(index, Slot::Enabled));
        assert_eq!(var.vr, 400 + 10 * i as u32);
        by_variables.set_boolean(var.vr, true).expect("set");
        for (name, value) in term.integer_parameters(index) {
            let vr = info().by_name(&name).expect(&name).vr;
            by_variables.set_integer(vr, value).expect("set");
            assert_eq!(by_variables.get_integer(vr).expect("get"), value);
        }
        for (name, value) in term.real_parameters(index) {
            let vr = info().by_name(&name).expect(&name).vr;
            by_variables.set_real(vr, value).expect("set");
            assert_eq!(by_variables.get_real(vr).expect("get"), value);
        }
    }
    assert_eq!(by_api.effects.discovered, by_variables.effects.discovered);
    let f = force(256);
    assert_eq!(drive(&mut by_api, &f), drive(&mut by_variables, &f));
    // A bad value through the variables is refused with the variable's name.
    let at = info().by_name("discovered4_at").expect("variable").vr;
    let error = by_variables
        .set_integer(at, 5)
        .expect_err("refused")
        .to_string();
    assert!(error.contains("discovered4_at"), "{error}");
}
