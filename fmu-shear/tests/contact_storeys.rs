//! The exact contact stepping on any building (`piecewise_any`) against the error-controlled
//! path (Dormand–Prince to `ADAPTIVE_TOLERANCE`, split at the kinks) and a fine reference (RK4
//! with `REFERENCE_SUBSTEPS` sub-steps split at the kinks), for N = 1, 2, 5, 10 under a force at
//! a floor and under ground acceleration, with the control force ramping on its floor and a
//! bumper at a low site (the ground and floor 1) and at a high one (floors N − 1 and N); and the
//! generic code on vectors against the rig's fixed-array path (both `piecewise_any`). The error measure is the
//! paper's NMSE of the accelerations an accelerometer reads (%), the worst floor.
//!
//! Print the table with `cargo test -p fmu-shear --test contact_storeys -- --nocapture`.

use fmu_shear::effects::{contact, Contact, Effects, Law};
use fmu_shear::integrate::dopri5_with_events;
use fmu_shear::linear::StepInputs;
use fmu_shear::piecewise_any::{AnyContactMaps, MAX_EXACT_CONTACTS};
use fmu_shear::{Integrator, ShearModel, ShearParameters};
use structure::{Excitation, Structure};

mod common;

const STEP: f64 = 1.0 / 51.2;
/// 10 s at 51.2 Hz.
const STEPS: usize = 512;
const REFERENCE_SUBSTEPS: u32 = 1024;

/// A building of `n` storeys, every floor and storey different (masses 4.1–5.9 kg, storey
/// stiffness 3300–5100 N/m, damping 0.4–8.1 N·s/m), the control force on floor
/// `control_floor`.
fn params(n: usize, excitation: Excitation, control_floor: usize) -> ShearParameters {
    let pick = |values: &[f64], i: usize| values[(3 * i + 1) % values.len()];
    let structure = Structure {
        mass: (0..n)
            .map(|i| pick(&[4.6, 5.3, 4.9, 5.8, 4.1, 5.9], i))
            .collect(),
        damping: (0..n)
            .map(|i| pick(&[8.1, 3.7, 2.6, 1.2, 0.4], i))
            .collect(),
        stiffness: (0..n)
            .map(|i| pick(&[3850.0, 4100.0, 4680.0, 3300.0, 5100.0, 4021.0, 4400.0], i))
            .collect(),
        excitation,
    };
    structure.validate().expect("a valid structure");
    let mut p = ShearParameters::from_structure(&structure);
    p.control_floor = control_floor;
    p
}

/// The excitation (1 N RMS force, or 0.5 m/s² RMS ground acceleration) and the control force
/// (a slower signal, a third of it), sampled at the steps.
fn inputs(excitation: Excitation) -> (Vec<f64>, Vec<f64>) {
    let scale = match excitation {
        Excitation::Force { .. } => 1.0,
        Excitation::Base => 0.5,
    };
    let e = common::band_limited_force(STEPS, STEP)
        .into_iter()
        .map(|f| scale * f)
        .collect();
    let c = (0..=STEPS)
        .map(|k| 0.3 * (0.11 * k as f64).cos() + 0.2 * (0.53 * k as f64).sin())
        .collect();
    (e, c)
}

fn step_inputs(e: &[f64], c: &[f64], k: usize) -> StepInputs {
    StepInputs {
        excitation: e[k],
        excitation_slope: (e[k + 1] - e[k]) / STEP,
        control: c[k],
        control_slope: (c[k + 1] - c[k]) / STEP,
    }
}

/// How a run is stepped.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Path {
    /// `integrator = 0`: the exact contact flows.
    Exact,
    /// The error-controlled path called directly.
    ErrorControlled,
    /// RK4 with this many sub-steps, split at the kinks (`integrator = 1`).
    Fixed(u32),
}

/// The accelerations an accelerometer reads on each floor after each step, and the model.
fn run(model: &ShearModel, e: &[f64], c: &[f64], path: Path) -> (Vec<Vec<f64>>, ShearModel) {
    let mut model = model.clone();
    let n = model.storeys();
    match path {
        Path::Fixed(substeps) => {
            model.integrator = Integrator::FixedSubsteps;
            model.params.substeps = substeps;
        }
        _ => model.integrator = Integrator::Exact,
    }
    let mut acc = vec![Vec::with_capacity(STEPS); n];
    let mut trial = 0.0;
    for k in 0..STEPS {
        let u = step_inputs(e, c, k);
        model.force.value = u.excitation;
        model.force.slope = u.excitation_slope;
        model.control_force.value = u.control;
        model.control_force.slope = u.control_slope;
        if path == Path::ErrorControlled {
            let mut x = model.displacement.clone();
            x.extend_from_slice(&model.velocity);
            let x = dopri5_with_events(&model, &x, &u, STEP, &mut trial);
            model.displacement.copy_from_slice(&x[..n]);
            model.velocity.copy_from_slice(&x[n..]);
            model.force.value = e[k + 1];
            model.control_force.value = c[k + 1];
            model.force.slope = 0.0;
            model.control_force.slope = 0.0;
        } else {
            model.advance(STEP);
        }
        for (series, a) in acc.iter_mut().zip(model.absolute_acceleration()) {
            series.push(a);
        }
    }
    (acc, model)
}

fn nmse(prediction: &[f64], reference: &[f64]) -> f64 {
    let count = reference.len() as f64;
    let mean = reference.iter().sum::<f64>() / count;
    let variance = reference.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / count;
    let squared: f64 = prediction
        .iter()
        .zip(reference)
        .map(|(p, r)| (p - r).powi(2))
        .sum();
    100.0 * squared / (count * variance)
}

fn worst(a: &[Vec<f64>], reference: &[Vec<f64>]) -> f64 {
    a.iter()
        .zip(reference)
        .map(|(a, r)| nmse(a, r))
        .fold(0.0, f64::max)
}

/// The largest |drift| of storey `s` of the linear model under the inputs.
fn largest_drift(model: &ShearModel, e: &[f64], c: &[f64], s: usize) -> f64 {
    let mut linear = model.clone();
    linear.effects = Effects::new(model.storeys());
    let mut largest = 0.0f64;
    let mut m = linear;
    for k in 0..STEPS {
        let u = step_inputs(e, c, k);
        m.force.value = u.excitation;
        m.force.slope = u.excitation_slope;
        m.control_force.value = u.control;
        m.control_force.slope = u.control_slope;
        m.advance(STEP);
        let y = &m.displacement;
        let d = if s == 0 { y[0] } else { y[s] - y[s - 1] };
        largest = largest.max(d.abs());
    }
    largest
}

/// The model of `n` storeys with bumpers at `sites` (storey, side), each gap `fraction` of the
/// storey's largest linear drift, 9000 N/m.
fn with_contacts(
    n: usize,
    excitation: Excitation,
    control_floor: usize,
    sites: &[(usize, i32)],
    fraction: f64,
) -> (ShearModel, Vec<f64>, Vec<f64>) {
    let linear = ShearModel::new(params(n, excitation, control_floor), Effects::new(n));
    let (e, c) = inputs(excitation);
    let mut model = linear.clone();
    for &(s, side) in sites {
        let gap = fraction * largest_drift(&linear, &e, &c, s);
        model.effects.switch_on(
            s,
            Law::Contact(Contact {
                gap,
                stiffness: 9000.0,
                side,
            }),
        );
    }
    (model, e, c)
}

/// Worst-floor NMSE (%) against the reference of the exact path and of the error-controlled
/// path, and how much the contacts move the response.
fn errors(model: &ShearModel, e: &[f64], c: &[f64]) -> (f64, f64, f64, ShearModel) {
    let (reference, _) = run(model, e, c, Path::Fixed(REFERENCE_SUBSTEPS));
    let (exact, stepped) = run(model, e, c, Path::Exact);
    let (controlled, _) = run(model, e, c, Path::ErrorControlled);
    let mut linear = model.clone();
    linear.effects = Effects::new(model.storeys());
    let (linear, _) = run(&linear, e, c, Path::Exact);
    (
        worst(&exact, &reference),
        worst(&controlled, &reference),
        worst(&linear, &reference),
        stepped,
    )
}

/// N = 1, 2, 5, 10, a force at the top floor (control on floor 1) or ground acceleration
/// (control on the top floor), one bumper at the ground storey or at the top storey (gap half
/// the storey's largest linear drift, closing on both sides), and for N ≥ 5 three at once
/// (ground positive, middle negative, top both). Every case steps exactly (the maps are
/// cached, a few regions), its contacts move the response by more than 0.1 % NMSE, and its
/// worst-floor NMSE against the reference stays under the paper path's bar for the examples'
/// bumper (`effects_accuracy.rs`: 1e-18 %) and under the error-controlled path's.
///
/// Measured worst-floor NMSE (%), exact / error-controlled: N = 1 3.7e-24 / 3.2e-15 (force),
/// 7.0e-24 / 4.7e-15 (base); N = 2 1.3e-22 to 4.4e-21 / 8.2e-14 to 1.3e-12; N = 5 1.4e-23 to
/// 1.4e-22 / 9.8e-16 to 1.8e-15; N = 10 2.2e-23 to 4.1e-22 / 8.3e-16 to 1.6e-14 (largely the
/// reference's own error). The bar is 230× the largest exact error (4.4e-21, N = 2, force,
/// top bumper).
#[test]
fn exact_contacts_on_any_building_against_a_fine_reference() {
    let mut table = Vec::new();
    for n in [1usize, 2, 5, 10] {
        for excitation in [Excitation::Force { floor: n }, Excitation::Base] {
            let control_floor = match excitation {
                Excitation::Base => n,
                Excitation::Force { .. } => 1,
            };
            let mut layouts: Vec<(String, Vec<(usize, i32)>)> = vec![
                ("ground".into(), vec![(0, contact::SIDE_BOTH)]),
                (format!("top {n}"), vec![(n - 1, contact::SIDE_BOTH)]),
            ];
            if n == 1 {
                layouts.pop();
            }
            if n >= 5 {
                layouts.push((
                    "three".into(),
                    vec![
                        (0, contact::SIDE_POSITIVE),
                        (n / 2, contact::SIDE_NEGATIVE),
                        (n - 1, contact::SIDE_BOTH),
                    ],
                ));
            }
            for (name, sites) in layouts {
                let (model, e, c) = with_contacts(n, excitation, control_floor, &sites, 0.5);
                let (exact, controlled, effect, stepped) = errors(&model, &e, &c);
                let case = format!("N = {n}, {excitation:?}, contacts {name}");
                println!(
                    "{case}: exact {exact:.1e} %, error-controlled {controlled:.1e} %, \
                     effect {effect:.1e} %"
                );
                let regions = stepped
                    .contact_maps
                    .as_ref()
                    .map(|m| m.cached_regions())
                    .unwrap_or(0);
                assert!(regions >= 2, "{case}: stepped exactly ({regions} regions)");
                assert!(effect > 0.1, "{case}: the contacts move the response");
                table.push((case, exact, controlled));
            }
        }
    }
    for (case, exact, controlled) in &table {
        assert!(
            *exact <= 1e-18 && exact <= controlled,
            "{case}: exact {exact:e} %, error-controlled {controlled:e} %"
        );
    }
}

/// The generic code on the paper's rig (three storeys, force at floor 1, control on floor 1)
/// steps as the rig's fixed-array path (`piecewise_any` on `[f64; 6]` with the net input, which
/// `integrator = 0` uses there; before, the rig's own fixed-array stepper): the
/// examples' bumper, three bumpers of different sides and a stiff one, each run's states equal
/// to 1e-12 of their peak (measured 2.3e-14 and 9.3e-14), the stiff one (1e6 N/m, whose
/// response the paper's test calls very sensitive) to 1e-11 (measured 3.1e-12).
#[test]
fn the_generic_code_on_the_paper_rig_equals_the_fixed_array_path() {
    let p = ShearParameters::default();
    assert!(structure::paper::is_paper_rig(&p.layout()));
    let (e, c) = inputs(Excitation::Force { floor: 1 });
    // (bumpers, steps that must end in contact at least, bar relative to the peak)
    type Case<'a> = (&'a [(usize, f64, f64, i32)], usize, f64);
    let cases: [Case; 3] = [
        (&[(2, 5e-4, 9000.0, contact::SIDE_BOTH)], STEPS / 20, 1e-12),
        (
            &[
                (0, 2e-3, 9000.0, contact::SIDE_POSITIVE),
                (1, 1e-3, 9000.0, contact::SIDE_NEGATIVE),
                (2, 3e-4, 9000.0, contact::SIDE_BOTH),
            ],
            STEPS / 20,
            1e-12,
        ),
        (&[(2, 5e-4, 1e6, contact::SIDE_BOTH)], 1, 1e-11),
    ];
    for (sites, in_contact, bar) in cases {
        let mut model = ShearModel::new(p.clone(), Effects::new(3));
        model.params.damping = vec![8.1, 3.7, 2.6];
        for &(s, gap, stiffness, side) in sites {
            model.effects.switch_on(
                s,
                Law::Contact(Contact {
                    gap,
                    stiffness,
                    side,
                }),
            );
        }
        // Against the run's peak of each kind (a relative error per value means nothing at
        // the zero crossings).
        let (mut dy, mut py, mut dv, mut pv) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let mut rig = model.clone();
        let mut generic = AnyContactMaps::new(&model, STEP);
        let mut x = vec![0.0; 6];
        let mut closed = 0;
        for k in 0..STEPS {
            let u = step_inputs(&e, &c, k);
            rig.force.value = u.excitation;
            rig.force.slope = u.excitation_slope;
            rig.control_force.value = u.control;
            rig.control_force.slope = u.control_slope;
            rig.advance(STEP);
            x = generic.advance(&x, &u).expect("finite");
            for i in 0..3 {
                dy = dy.max((x[i] - rig.displacement[i]).abs());
                py = py.max(rig.displacement[i].abs());
                dv = dv.max((x[3 + i] - rig.velocity[i]).abs());
                pv = pv.max(rig.velocity[i].abs());
            }
            if model.effects.force(&rig.displacement, &rig.velocity) != vec![0.0; 3] {
                closed += 1;
            }
        }
        println!(
            "paper rig, contacts {sites:?}: generic vs fixed arrays {:.1e} of the peak \
             displacement, {:.1e} of the peak velocity; {closed} of {STEPS} steps end in contact",
            dy / py,
            dv / pv
        );
        assert!(closed >= in_contact, "the bumpers close ({closed} steps)");
        assert!(
            dy <= bar * py && dv <= bar * pv,
            "{dy:e} of {py:e}, {dv:e} of {pv:e}"
        );
    }
}

/// More contacts than the exact path takes step with the error-controlled path (no maps
/// built), and the two agree where both apply: ten storeys with nine bumpers against the same
/// with eight. And a contact leaves the sensitivities NaN (they are the linear model's).
#[test]
fn too_many_contacts_step_error_controlled() {
    let n = 10;
    let excitation = Excitation::Base;
    let sites: Vec<(usize, i32)> = (0..=MAX_EXACT_CONTACTS)
        .map(|s| (s, contact::SIDE_BOTH))
        .collect();
    let (model, e, c) = with_contacts(n, excitation, n, &sites, 0.7);
    let (_, stepped) = run(&model, &e, &c, Path::Exact);
    assert!(stepped.contact_maps.is_none(), "nine contacts: no maps");
    let mut eight = model.clone();
    eight.effects.contact.enable(MAX_EXACT_CONTACTS, false);
    let (a, stepped) = run(&eight, &e, &c, Path::Exact);
    assert!(stepped.contact_maps.is_some(), "eight contacts: exact");
    let (b, _) = run(&eight, &e, &c, Path::ErrorControlled);
    let difference = worst(&a, &b);
    println!("eight contacts, exact against error-controlled: {difference:.1e} %");
    assert!(difference < 1e-9, "{difference:e} %");

    let mut sensitive = stepped;
    sensitive.sensitivities.on = true;
    let mut x = sensitive.displacement.clone();
    x.extend_from_slice(&sensitive.velocity);
    let value = sensitive.sensitivities.output(
        &sensitive.params,
        &sensitive.effects,
        &x,
        &StepInputs::default(),
        0,
        0,
    );
    assert!(value.is_nan());
}

/// A calibration runs one structure again and again with a contact's gap and stiffness
/// changed: the maps adapted from the last run keep the regions whose system is unchanged (the
/// open one, whatever the contact) and step exactly as maps built afresh, to the bit — on five
/// storeys (`piecewise_any`) and on the paper's rig (through the model). A change of
/// the structure keeps none.
#[test]
fn adapted_maps_step_as_fresh_ones_to_the_bit() {
    let (e, c) = inputs(Excitation::Force { floor: 1 });
    let with_contact = |n: usize, gap: f64, stiffness: f64| {
        let mut model = ShearModel::new(
            params(n, Excitation::Force { floor: 1 }, n),
            Effects::new(n),
        );
        model.effects.switch_on(
            n - 1,
            Law::Contact(Contact {
                gap,
                stiffness,
                side: contact::SIDE_BOTH,
            }),
        );
        model
    };
    let states = |maps: &mut AnyContactMaps, n: usize| -> Vec<Vec<f64>> {
        let mut x = vec![0.0; 2 * n];
        (0..STEPS)
            .map(|k| {
                x = maps.advance(&x, &step_inputs(&e, &c, k)).expect("finite");
                x.clone()
            })
            .collect()
    };
    let n = 5;
    let first = with_contact(n, 4e-4, 9000.0);
    let mut maps = AnyContactMaps::new(&first, STEP);
    states(&mut maps, n);
    let visited = maps.regions_cached();
    assert!(visited >= 2, "the run visits the open and a closed region");
    // The gap and the stiffness a fit would try next.
    let next = with_contact(n, 4.1e-4, 9500.0);
    maps.adapt(&next, STEP);
    assert_eq!(maps.regions_cached(), 1, "the open region alone is kept");
    let mut fresh = AnyContactMaps::new(&next, STEP);
    assert_eq!(states(&mut maps, n), states(&mut fresh, n));
    // Another structure: nothing kept.
    let mut stiffer = next.clone();
    stiffer.params.stiffness[0] *= 1.01;
    maps.adapt(&stiffer, STEP);
    assert_eq!(maps.regions_cached(), 0);

    // The rig, through the model: a reset keeps its maps for the next run.
    let rig = |gap: f64, stiffness: f64| {
        let mut model = with_contact(3, gap, stiffness);
        model.params = ShearParameters::default();
        model
    };
    let run = |mut model: ShearModel| -> (Vec<Vec<f64>>, ShearModel) {
        let mut out = Vec::with_capacity(STEPS);
        for k in 0..STEPS {
            let u = step_inputs(&e, &c, k);
            model.force.value = u.excitation;
            model.force.slope = u.excitation_slope;
            model.advance(STEP);
            out.push(model.displacement.clone());
        }
        model.displacement = vec![0.0; 3];
        model.velocity = vec![0.0; 3];
        (out, model)
    };
    let (_, used) = run(rig(4e-4, 9000.0));
    let visited = used.contact_maps.as_ref().map_or(0, |m| m.regions_cached());
    assert!(
        visited >= 2,
        "the rig's run visits the open and a closed region"
    );
    let mut reused = rig(4.1e-4, 9500.0);
    reused.contact_maps = used.contact_maps;
    let (again, reused) = run(reused);
    let (afresh, _) = run(rig(4.1e-4, 9500.0));
    assert_eq!(again, afresh);
    assert!(reused.contact_maps.is_some_and(|m| m.regions_cached() >= 2));
}
