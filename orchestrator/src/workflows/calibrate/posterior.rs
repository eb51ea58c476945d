//! The Laplace posterior at the optimum and what the calibration found on each record.

use super::prior::Space;
use super::problem::over_columns;
use super::target::{raw_residuals, sensitivity_normals, sse_per_block, ModelNormals, Target};
use super::{CalibrateError, CalibrationSetup, ParameterEstimate, RecordCalibration};
use crate::twin::data::Measurement;
use crate::twin::simulator::Simulator;
use nalgebra::DMatrix;

/// The residuals at `z` and their Jacobian by central differences (2p runs per record).
pub(super) fn central_differences<'a>(
    sims: &mut [Simulator<'a>],
    target: &Target<'a>,
    z: &[f64],
) -> Option<(Vec<f64>, DMatrix<f64>)> {
    let mut buf: Vec<Vec<f64>> = Vec::new();
    let r0 = raw_residuals(sims, target, z, &mut buf)?;
    let mut jac = DMatrix::zeros(r0.len(), z.len());
    let columns = over_columns(sims, &mut buf, target, z.len(), |sims, buf, j| {
        let h = 1e-4 * z[j].abs().max(1.0);
        let (mut zp, mut zm) = (z.to_vec(), z.to_vec());
        zp[j] += h;
        zm[j] -= h;
        let rp = raw_residuals(sims, target, &zp, buf)?;
        let rm = raw_residuals(sims, target, &zm, buf)?;
        Some(
            rp.iter()
                .zip(&rm)
                .map(|(p, m)| (p - m) / (2.0 * h))
                .collect::<Vec<f64>>(),
        )
    })?;
    for (j, c) in columns.iter().enumerate() {
        jac.column_mut(j).copy_from_slice(c);
    }
    Some((r0, jac))
}

/// The Laplace approximation at (z, s): covariance of (z, s), `s` every block's log σ² after
/// the parameters. Also the FMU runs it made.
pub(super) fn laplace<'a>(
    sims: &mut [Simulator<'a>],
    target: &Target<'a>,
    z: &[f64],
    s: &[f64],
) -> Option<(DMatrix<f64>, usize)> {
    let p = z.len();
    let records = target.records.len();
    let blocks = target.blocks();
    let (model, runs) = match sensitivity_normals(sims, target, z) {
        Some(exact) => (exact, records),
        None => {
            let (r0, jac) = central_differences(sims, target, z)?;
            let model = ModelNormals::from_jacobian(r0, &jac, &blocks);
            (model, (2 * p + 1) * records)
        }
    };
    let sse = sse_per_block(&model.r, &blocks);
    let q = blocks.len();
    let mut hess = DMatrix::zeros(p + q, p + q);
    for (b, (jtj, jtr)) in model.blocks.iter().enumerate() {
        let w = (-s[b]).exp();
        for a in 0..p {
            for c in 0..p {
                hess[(a, c)] += w * jtj[(a, c)];
            }
            hess[(a, p + b)] = -w * jtr[a];
            hess[(p + b, a)] = -w * jtr[a];
        }
        hess[(p + b, p + b)] = sse[b] * w / 2.0 + 1.0 / target.noise_var;
    }
    for a in 0..p {
        hess[(a, a)] += 1.0;
    }
    Some((hess.try_inverse()?, runs))
}

/// The samples the likelihood uses: after the transient, where the mask (if any) is set.
/// Also the first sample after the transient.
pub(super) fn used_samples(
    data: &Measurement,
    mask: Option<&[bool]>,
    transient: f64,
) -> Result<(usize, Vec<usize>), CalibrateError> {
    let first = crate::evaluation::stats::first_after_transient(&data.time, transient);
    if let Some(mask) = mask {
        if mask.len() != data.len() {
            return Err(CalibrateError::Setup(format!(
                "{}: the sample mask has {} entries for a record of {} samples",
                data.path.display(),
                mask.len(),
                data.len()
            )));
        }
    }
    let used: Vec<usize> = (first..data.len())
        .filter(|&k| mask.map_or(true, |m| m[k]))
        .collect();
    if used.len() < 10 {
        return Err(CalibrateError::Setup(format!(
            "{}: the transient cut-off of {} s and the sample mask leave {} samples",
            data.path.display(),
            transient,
            used.len()
        )));
    }
    Ok((first, used))
}
/// The Laplace posterior of the calibrated parameters.
pub(super) struct Posterior {
    pub(super) parameters: Vec<ParameterEstimate>,
    pub(super) correlation: Vec<Vec<f64>>,
    pub(super) log_evidence: f64,
}

impl Posterior {
    /// The posterior at the optimum `values` (negative log posterior `objective` there), from
    /// the covariance `cov` of the standardised parameters and the log noise variances: each
    /// parameter's estimate and sd, their correlations, and the log evidence.
    pub(super) fn at(
        target: &Target,
        setup: &CalibrationSetup,
        values: &[f64],
        cov: &DMatrix<f64>,
        objective: f64,
    ) -> Posterior {
        let p = setup.parameters.len();
        let parameters = (0..p)
            .map(|j| {
                let prior = target.priors[j];
                let sd_coordinate = prior.sd() * cov[(j, j)].max(0.0).sqrt();
                let sd = match prior.space {
                    Space::Linear => sd_coordinate,
                    Space::Log => values[j] * sd_coordinate,
                };
                ParameterEstimate {
                    name: setup.parameters[j].clone(),
                    value: values[j],
                    prior,
                    sd_coordinate,
                    sd,
                }
            })
            .collect();
        let correlation = (0..p)
            .map(|a| {
                (0..p)
                    .map(|b| cov[(a, b)] / (cov[(a, a)] * cov[(b, b)]).sqrt())
                    .collect()
            })
            .collect();
        let log_evidence = match cov.clone().cholesky() {
            Some(chol) => {
                let log_det: f64 = chol.l().diagonal().iter().map(|d| 2.0 * d.ln()).sum();
                -objective + 0.5 * log_det
            }
            None => f64::NEG_INFINITY,
        };
        Posterior {
            parameters,
            correlation,
            log_evidence,
        }
    }
}

/// What the calibration found on each record at the optimum (`values`, the log noise
/// variances `s`, covariance `cov`): its noise variances with their posterior sd, and the fit's
/// NMSE per channel after the record's transient (`firsts`), one run per record.
pub(super) fn record_fits(
    sims: &mut [Simulator],
    target: &Target,
    firsts: &[usize],
    values: &[f64],
    s: &[f64],
    cov: &DMatrix<f64>,
) -> Result<Vec<RecordCalibration>, CalibrateError> {
    let p = target.priors.len();
    let mut buf: Vec<Vec<f64>> = Vec::new();
    let mut fitted = Vec::with_capacity(target.records.len());
    let mut block = 0;
    for ((sim, record), &first) in sims.iter_mut().zip(&target.records).zip(firsts) {
        buf.resize(record.channels.len(), Vec::new());
        sim.record(&target.vrs, values, &record.outputs(), &mut buf)?;
        let q = record.channels.len();
        let blocks = block..block + q;
        block += q;
        fitted.push(RecordCalibration {
            record: record.data.path.display().to_string(),
            channels: record.channels.iter().map(|c| c.name.clone()).collect(),
            noise_variance: blocks.clone().map(|b| s[b].exp()).collect(),
            noise_log_sd: blocks
                .map(|b| cov[(p + b, p + b)].max(0.0).sqrt())
                .collect(),
            samples_used: record.used.len(),
            nmse: record
                .channels
                .iter()
                .zip(&buf)
                .map(|(c, predicted)| {
                    crate::evaluation::compare::nmse(&c.values[first..], &predicted[first..])
                })
                .collect(),
        });
    }
    Ok(fitted)
}
