//! The twin's modes with their uncertainty. The modes are those of the twin's linear structure
//! (`Twin::structure`: masses, storey dampings and stiffnesses; effects of the library left out,
//! which is their state at rest for a gap contact and a cubic stiffness). Each frequency,
//! damping ratio and shape component gets a standard deviation from the Laplace posterior of
//! the calibrated parameters stored in the twin: the first-order sensitivities (the eigenvalue
//! sensitivity of `numerics::modal::eigen` for frequency and damping, central differences for
//! the shapes) through the covariance, `sd² = gᵀ Σ g`. Parameters of the covariance that are not
//! masses, dampings or stiffnesses (an effect's) do not move the linear modes. The linearised
//! sd is checked against sampling the posterior: the same figures from `samples` draws.

use nalgebra::DMatrix;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use serde::Serialize;

use super::ModalError;
use crate::twin::{ParameterCovariance, Twin};
use ::structure::Structure;
use numerics::modal::{modes, Mode};

/// What `twin modal --twin` computes beyond the modes.
#[derive(Debug, Clone)]
pub struct ModalOptions {
    /// Draws from the posterior for the sampling check (0: none).
    pub samples: usize,
    pub seed: u64,
}

impl Default for ModalOptions {
    fn default() -> Self {
        ModalOptions {
            samples: 2000,
            seed: 20261127,
        }
    }
}

/// One mode of the twin.
#[derive(Debug, Clone, Serialize)]
pub struct TwinMode {
    /// 1 for the lowest frequency.
    pub number: usize,
    /// Natural frequency, Hz.
    pub frequency: f64,
    /// Its posterior sd (linearised), Hz; None for an uncalibrated twin.
    pub frequency_sd: Option<f64>,
    /// Damping ratio.
    pub damping: f64,
    pub damping_sd: Option<f64>,
    /// Floors 1..N, the largest component 1.
    pub shape: Vec<f64>,
    pub shape_sd: Option<Vec<f64>>,
    /// The same sds from sampling the posterior (the check of the linearisation).
    pub sampled: Option<SampledSd>,
}

#[derive(Debug, Clone, Serialize)]
pub struct SampledSd {
    pub draws: usize,
    pub frequency_sd: f64,
    pub damping_sd: f64,
}

/// The twin's modes, with what their uncertainty rests on.
#[derive(Debug, Clone, Serialize)]
pub struct TwinModes {
    pub twin: String,
    pub storeys: usize,
    /// `force:K` or `base`.
    pub excitation: String,
    pub modes: Vec<TwinMode>,
    /// The calibrated parameters whose covariance the sds carry (masses, dampings, stiffnesses).
    pub uncertain_parameters: Vec<String>,
    /// Parameters of the covariance that do not enter the linear modes (an effect's).
    pub other_parameters: Vec<String>,
}

/// The modes of `twin` with their sds.
pub fn twin_modes(twin: &Twin, options: &ModalOptions) -> Result<TwinModes, ModalError> {
    let structure = twin.structure()?;
    structure.validate()?;
    let nominal = structure_modes(&structure)?;
    let storeys = structure.storeys();
    let mut result: Vec<TwinMode> = nominal
        .iter()
        .enumerate()
        .map(|(i, mode)| TwinMode {
            number: i + 1,
            frequency: mode.frequency,
            frequency_sd: None,
            damping: mode.damping,
            damping_sd: None,
            shape: mode.real_shape(),
            shape_sd: None,
            sampled: None,
        })
        .collect();
    let names = structure.parameter_names();
    let (uncertain, other): (Vec<String>, Vec<String>) = match &twin.parameter_covariance {
        Some(cov) => cov.names.iter().cloned().partition(|n| names.contains(n)),
        None => (Vec::new(), Vec::new()),
    };
    if let Some(cov) = &twin.parameter_covariance {
        let sigma = sub_covariance(cov, &uncertain);
        linearised_sds(&structure, &nominal, &uncertain, &sigma, &mut result)?;
        if options.samples > 0 {
            sampled_sds(
                &structure,
                &nominal,
                &uncertain,
                &sigma,
                options,
                &mut result,
            )?;
        }
    }
    Ok(TwinModes {
        twin: twin.describe(),
        storeys,
        excitation: structure.excitation.name(),
        modes: result,
        uncertain_parameters: uncertain,
        other_parameters: other,
    })
}

/// The underdamped modes of a structure.
pub fn structure_modes(structure: &Structure) -> Result<Vec<Mode>, ModalError> {
    Ok(modes(
        &structure.mass_matrix(),
        &structure.damping_matrix(),
        &structure.stiffness_matrix(),
    )?)
}

fn sub_covariance(cov: &ParameterCovariance, names: &[String]) -> DMatrix<f64> {
    let index: Vec<usize> = names
        .iter()
        .map(|n| cov.names.iter().position(|m| m == n).unwrap_or(usize::MAX))
        .collect();
    DMatrix::from_fn(names.len(), names.len(), |a, b| {
        cov.matrix
            .get(index[a])
            .and_then(|row| row.get(index[b]))
            .copied()
            .unwrap_or(0.0)
    })
}

/// The matrices' derivatives to one parameter: each matrix is linear in its own vector, so the
/// structure with that parameter 1 and every other 0 gives them.
fn unit_structure(structure: &Structure, name: &str) -> Structure {
    let n = structure.storeys();
    let mut unit = Structure {
        mass: vec![0.0; n],
        damping: vec![0.0; n],
        stiffness: vec![0.0; n],
        excitation: structure.excitation,
    };
    unit.set(name, 1.0);
    unit
}

/// The real shape scaled to 1 at floor `at` (the nominal's largest component), so that the
/// shapes of nearby parameter values are compared component by component.
fn shape_at(mode: &Mode, at: usize) -> Vec<f64> {
    let pivot = mode.shape[at];
    mode.shape.iter().map(|c| (c / pivot).re).collect()
}

fn pivot(shape: &[f64]) -> usize {
    shape
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .map(|(i, _)| i)
        .unwrap_or(0)
}

fn quadratic_form(g: &[f64], sigma: &DMatrix<f64>) -> f64 {
    let mut s = 0.0;
    for a in 0..g.len() {
        for b in 0..g.len() {
            s += g[a] * sigma[(a, b)] * g[b];
        }
    }
    s.max(0.0)
}

fn linearised_sds(
    structure: &Structure,
    nominal: &[Mode],
    names: &[String],
    sigma: &DMatrix<f64>,
    result: &mut [TwinMode],
) -> Result<(), ModalError> {
    let (m, c) = (structure.mass_matrix(), structure.damping_matrix());
    let p = names.len();
    // Per mode: gradients of frequency, damping and each shape component.
    let mut grad_f = vec![vec![0.0; p]; nominal.len()];
    let mut grad_z = vec![vec![0.0; p]; nominal.len()];
    let mut grad_shape = vec![vec![vec![0.0; p]; structure.storeys()]; nominal.len()];
    for (j, name) in names.iter().enumerate() {
        let unit = unit_structure(structure, name);
        let (dm, dc, dk) = (
            unit.mass_matrix(),
            unit.damping_matrix(),
            unit.stiffness_matrix(),
        );
        for (i, mode) in nominal.iter().enumerate() {
            let dl = mode.eigenvalue_change(&m, &c, &dm, &dc, &dk);
            let (df, dz) = mode.frequency_damping_change(dl);
            grad_f[i][j] = df;
            grad_z[i][j] = dz;
        }
        // Shapes: central differences with a relative step of 1e-4.
        let value = structure.get(name).unwrap_or(0.0);
        let h = value.abs().max(1e-12) * 1e-4;
        let shifted = |sign: f64| -> Result<Vec<Mode>, ModalError> {
            let mut s = structure.clone();
            s.set(name, value + sign * h);
            structure_modes(&s)
        };
        let (plus, minus) = (shifted(1.0)?, shifted(-1.0)?);
        if plus.len() != nominal.len() || minus.len() != nominal.len() {
            continue;
        }
        for (i, mode) in nominal.iter().enumerate() {
            let at = pivot(&mode.real_shape());
            let (sp, sm) = (shape_at(&plus[i], at), shape_at(&minus[i], at));
            for floor in 0..structure.storeys() {
                grad_shape[i][floor][j] = (sp[floor] - sm[floor]) / (2.0 * h);
            }
        }
    }
    for (i, mode) in result.iter_mut().enumerate() {
        mode.frequency_sd = Some(quadratic_form(&grad_f[i], sigma).sqrt());
        mode.damping_sd = Some(quadratic_form(&grad_z[i], sigma).sqrt());
        mode.shape_sd = Some(
            grad_shape[i]
                .iter()
                .map(|g| quadratic_form(g, sigma).sqrt())
                .collect(),
        );
    }
    Ok(())
}

/// A square root of Σ (symmetric, perhaps only semi-definite): V · sqrt(max(Λ, 0)).
fn covariance_root(sigma: &DMatrix<f64>) -> DMatrix<f64> {
    let eig = sigma.clone().symmetric_eigen();
    let mut root = eig.eigenvectors.clone();
    for (j, &l) in eig.eigenvalues.iter().enumerate() {
        let s = l.max(0.0).sqrt();
        root.column_mut(j).scale_mut(s);
    }
    root
}

fn sampled_sds(
    structure: &Structure,
    nominal: &[Mode],
    names: &[String],
    sigma: &DMatrix<f64>,
    options: &ModalOptions,
    result: &mut [TwinMode],
) -> Result<(), ModalError> {
    let root = covariance_root(sigma);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(options.seed);
    let p = names.len();
    let values: Vec<f64> = names
        .iter()
        .map(|n| structure.get(n).unwrap_or(0.0))
        .collect();
    let mut freqs = vec![Vec::with_capacity(options.samples); nominal.len()];
    let mut damps = vec![Vec::with_capacity(options.samples); nominal.len()];
    for _ in 0..options.samples {
        let z: Vec<f64> = (0..p).map(|_| StandardNormal.sample(&mut rng)).collect();
        let mut s = structure.clone();
        for (a, name) in names.iter().enumerate() {
            let shift: f64 = (0..p).map(|b| root[(a, b)] * z[b]).sum();
            s.set(name, values[a] + shift);
        }
        // A draw with a non-positive mass or stiffness has no structure: left out (counted).
        if s.validate().is_err() {
            continue;
        }
        let drawn = match structure_modes(&s) {
            Ok(d) if d.len() == nominal.len() => d,
            _ => continue,
        };
        for (i, mode) in drawn.iter().enumerate() {
            freqs[i].push(mode.frequency);
            damps[i].push(mode.damping);
        }
    }
    for (i, mode) in result.iter_mut().enumerate() {
        if freqs[i].len() < 2 {
            continue;
        }
        mode.sampled = Some(SampledSd {
            draws: freqs[i].len(),
            frequency_sd: sample_sd(&freqs[i]),
            damping_sd: sample_sd(&damps[i]),
        });
    }
    Ok(())
}

fn sample_sd(x: &[f64]) -> f64 {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
}
