//! What a calibration works on: its records, channels and priors, and the residuals and
//! normal equations of a trial.

use super::prior::{Prior, Space};
use super::CalibrationSetup;
use crate::cosim::import::Fmu;
use crate::twin::data::Measurement;
use crate::twin::linear::LinearFit;
use crate::twin::simulator::{sensitivity_switch, Simulator};
use crate::twin::{Component, ParameterValue, TwinError};
use nalgebra::{DMatrix, DVector};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};

/// One measured response of one record: its values, the FMU output predicting it and its own
/// noise prior.
pub(super) struct ChannelTarget<'a> {
    pub(super) name: String,
    pub(super) values: &'a [f64],
    /// The FMU's output of the same name (`acc2`, `vel1`, `disp3`).
    pub(super) output: u32,
    /// `d_{name}_d_{p}` for the calibrated parameters, when the FMU has them all.
    pub(super) sensitivities: Option<Vec<u32>>,
    /// Prior mean of log σ² for this channel of this record: from its own measured variance.
    pub(super) noise_mean: f64,
}

/// One record of a calibration: its excitation, its measured channels, the samples the
/// likelihood uses.
pub(super) struct RecordTarget<'a> {
    pub(super) data: &'a Measurement,
    /// The FMU input the excitation drives (`force` or `ground_acc`).
    pub(super) input: String,
    /// Sample indices the likelihood uses.
    pub(super) used: Vec<usize>,
    pub(super) channels: Vec<ChannelTarget<'a>>,
}

impl RecordTarget<'_> {
    pub(super) fn outputs(&self) -> Vec<u32> {
        self.channels.iter().map(|c| c.output).collect()
    }
}

/// What one calibration works on, shared by the threads: one or more records, one parameter
/// vector. The residuals are the records' in turn, each channel-major (record r, channel c is
/// one block with its own noise variance).
pub(super) struct Target<'a> {
    pub(super) fmu: &'a Fmu,
    pub(super) base: BTreeMap<String, ParameterValue>,
    pub(super) records: Vec<RecordTarget<'a>>,
    pub(super) vrs: Vec<u32>,
    pub(super) priors: Vec<Prior>,
    pub(super) noise_var: f64,
    pub(super) budget: usize,
    /// The FMU's forward sensitivities of the measured outputs to the calibrated parameters,
    /// when it offers them for all of them.
    pub(super) sensitivity: Option<Sensitivity>,
    /// The same in process, when the twin is the linear shear model and the calibrated
    /// parameters its `m`, `c`, `k` ([`LinearFit`]).
    pub(super) linear: Option<LinearFit>,
    /// Threads one start's finite-difference columns may use: the cores the starts leave idle
    /// (a single start on two cores: two).
    pub(super) columns_threads: usize,
}

/// Where an FMU gives `∂y/∂p` along a run: the Boolean parameter that switches them on (the
/// outputs `d_{channel}_d_{p}` are each channel's). The shear FMU carries them for its linear
/// model (`fmu_shear::sensitivity`); with an effect on they are NaN, and the calibration falls
/// back to finite differences.
pub(super) struct Sensitivity {
    pub(super) switch: u32,
    /// Set once a sensitivity run gave non-finite values: finite differences from then on.
    pub(super) failed: AtomicBool,
}

impl Sensitivity {
    pub(super) fn find(fmu: &Fmu) -> Option<Self> {
        Some(Sensitivity {
            switch: sensitivity_switch(fmu)?,
            failed: AtomicBool::new(false),
        })
    }
}

impl Target<'_> {
    pub(super) fn values(&self, z: &[f64]) -> Vec<f64> {
        z.iter()
            .zip(&self.priors)
            .map(|(z, p)| p.value(p.mean + p.sd() * z))
            .collect()
    }
    /// The residual blocks (record, channel) as (first row, rows).
    pub(super) fn blocks(&self) -> Vec<(usize, usize)> {
        let mut at = 0;
        let mut out = Vec::new();
        for r in &self.records {
            for _ in &r.channels {
                out.push((at, r.used.len()));
                at += r.used.len();
            }
        }
        out
    }
    pub(super) fn rows(&self) -> usize {
        self.records
            .iter()
            .map(|r| r.channels.len() * r.used.len())
            .sum()
    }
    /// Every block's prior mean of log σ², in block order.
    pub(super) fn noise_means(&self) -> Vec<f64> {
        self.records
            .iter()
            .flat_map(|r| r.channels.iter().map(|c| c.noise_mean))
            .collect()
    }
    /// Whether every channel of every record has its sensitivities.
    pub(super) fn sensitive(&self) -> bool {
        self.records
            .iter()
            .all(|r| r.channels.iter().all(|c| c.sensitivities.is_some()))
    }
}

/// One simulator per record (its excitation), for one thread.
pub(super) fn simulators<'a>(
    target: &Target<'a>,
    name: &str,
) -> Result<Vec<Simulator<'a>>, TwinError> {
    target
        .records
        .iter()
        .map(|r| {
            Simulator::driven(
                target.fmu,
                target.base.clone(),
                &r.input,
                &r.data.excitation.values,
                r.data.time[0],
                r.data.dt,
                name,
            )
        })
        .collect()
}

/// Residuals `y − ŷ` after the transient for parameters `z`, every record in turn, or None if
/// the FMU refused them (out of range, or the simulation diverged).
pub(super) fn raw_residuals(
    sims: &mut [Simulator],
    target: &Target,
    z: &[f64],
    buf: &mut Vec<Vec<f64>>,
) -> Option<Vec<f64>> {
    let values = target.values(z);
    if values.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let mut r = Vec::with_capacity(target.rows());
    for (sim, record) in sims.iter_mut().zip(&target.records) {
        buf.resize(record.channels.len(), Vec::new());
        sim.record(&target.vrs, &values, &record.outputs(), buf)
            .ok()?;
        for (c, predicted) in record.channels.iter().zip(buf.iter()) {
            for &k in &record.used {
                r.push(c.values[k] - predicted[k]);
            }
        }
    }
    Some(r)
}

/// The residuals `y − ŷ` for parameters `z` and their Jacobian `∂(y − ŷ)/∂z` (rows as the
/// residuals), from one run per record with the FMU's sensitivities; None when the FMU has none
/// for these parameters, refused them, or gave non-finite ones (an FMU's: then never again for
/// this calibration).
pub(super) fn sensitivity_jacobian(
    sims: &mut [Simulator],
    target: &Target,
    z: &[f64],
) -> Option<(Vec<f64>, DMatrix<f64>)> {
    let sensitivity = target.sensitivity.as_ref()?;
    if sensitivity.failed.load(Ordering::Relaxed) {
        return None;
    }
    let values = target.values(z);
    if values.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let p = z.len();
    let rows = target.rows();
    let mut r = Vec::with_capacity(rows);
    let mut jac = DMatrix::zeros(rows, p);
    let scale = prior_scales(target, &values);
    let mut row0 = 0;
    let mut through_fmi = false;
    for (sim, record) in sims.iter_mut().zip(&target.records) {
        let q = record.channels.len();
        // The linear shear model in process where the twin is it (the FMU's own maps, a pass
        // over the record), else the FMU's run with its sensitivities through FMI: the
        // predictions, then each channel's derivatives.
        let out = match target
            .linear
            .as_ref()
            .and_then(|fit| linear_outputs(fit, record, &values))
        {
            Some(out) => out,
            None => {
                through_fmi = true;
                let mut outputs = record.outputs();
                for c in &record.channels {
                    outputs.extend(c.sensitivities.as_ref()?);
                }
                let mut out: Vec<Vec<f64>> = vec![Vec::new(); outputs.len()];
                sim.record_switched(&target.vrs, &values, sensitivity.switch, &outputs, &mut out)
                    .ok()?;
                out
            }
        };
        let per = record.used.len();
        for (f, c) in record.channels.iter().enumerate() {
            r.extend(record.used.iter().map(|&k| c.values[k] - out[f][k]));
            for (j, scale) in scale.iter().enumerate() {
                let d = &out[q + f * p + j];
                let mut column = jac.column_mut(j);
                for (i, &k) in record.used.iter().enumerate() {
                    column[row0 + f * per + i] = -d[k] * scale;
                }
            }
        }
        row0 += q * per;
    }
    if jac.iter().any(|d| !d.is_finite()) {
        // An FMU whose sensitivities are not finite (NaN with an effect on) is asked no more;
        // the linear model in process gives non-finite ones only where the parameters blow
        // the run up (a start's wide draw), which says nothing of the other trials: before,
        // one such trial sent every start of a 10-storey calibration to finite differences
        // through FMI (5,235 of its runs, 6.2 s).
        if through_fmi {
            sensitivity.failed.store(true, Ordering::Relaxed);
        }
        return None;
    }
    Some((r, jac))
}

/// What the FMU's sensitivity run records for `record` (each channel's predictions, then its
/// derivatives along the calibrated parameters), from the linear model in process; None when
/// a channel is not an accelerometer or the FMU would refuse `values`.
pub(super) fn linear_outputs(
    fit: &LinearFit,
    record: &RecordTarget,
    values: &[f64],
) -> Option<Vec<Vec<f64>>> {
    let names: Vec<&str> = record.channels.iter().map(|c| c.name.as_str()).collect();
    let floors = fit.floors(&names)?;
    let (q, p) = (floors.len(), values.len());
    let mut out: Vec<Vec<f64>> = vec![Vec::with_capacity(record.data.len()); q * (p + 1)];
    fit.run(
        values,
        record.data,
        &floors,
        |_, predictions, derivatives| {
            for c in 0..q {
                out[c].push(predictions[c]);
                for j in 0..p {
                    out[q + c * p + j].push(derivatives[c * p + j]);
                }
            }
        },
    )?;
    Some(out)
}

/// The model's normal equations at a point: the residuals `y − ŷ` (every block in turn) and,
/// per block (record, channel), `J_bᵀ J_b` and `J_bᵀ r_b` with `J_b = ∂(y − ŷ)/∂z` of its rows.
pub(super) struct ModelNormals {
    pub(super) r: Vec<f64>,
    pub(super) blocks: Vec<(DMatrix<f64>, DVector<f64>)>,
}

impl ModelNormals {
    pub(super) fn from_jacobian(
        r: Vec<f64>,
        jac: &DMatrix<f64>,
        blocks: &[(usize, usize)],
    ) -> Self {
        let blocks = blocks
            .iter()
            .map(|&(start, per)| {
                let jf = jac.rows(start, per);
                let rf = DVector::from_column_slice(&r[start..start + per]);
                (jf.transpose() * jf, jf.transpose() * rf)
            })
            .collect();
        ModelNormals { r, blocks }
    }

    /// The normal equations of the weighted residuals and the prior's rows (`[w ∘ r; z]`):
    /// `Σ_b w_b² J_bᵀ J_b + I` and `Σ_b w_b² J_bᵀ r_b + z`, `w_b` block b's weight.
    pub(super) fn weighted(
        &self,
        block_weights: &[f64],
        z: &[f64],
    ) -> (DMatrix<f64>, DVector<f64>) {
        let p = z.len();
        let mut a = DMatrix::identity(p, p);
        let mut g = DVector::from_column_slice(z);
        for ((jtj, jtr), w) in self.blocks.iter().zip(block_weights) {
            let w2 = w * w;
            a += jtj * w2;
            g += jtr * w2;
        }
        (a, g)
    }
}

/// [`ModelNormals`] at `z`: through the linear model's modes in process where the twin is that
/// model ([`LinearFit::normals`]: a Gram matrix of the modes' responses, no Jacobian formed),
/// else from [`sensitivity_jacobian`]. None where that is.
pub(super) fn sensitivity_normals(
    sims: &mut [Simulator],
    target: &Target,
    z: &[f64],
) -> Option<ModelNormals> {
    if let Some(normals) = target
        .linear
        .as_ref()
        .and_then(|fit| linear_normals(fit, target, z))
    {
        return Some(normals);
    }
    let (r, jac) = sensitivity_jacobian(sims, target, z)?;
    Some(ModelNormals::from_jacobian(r, &jac, &target.blocks()))
}

/// [`ModelNormals`] from the linear model's modes in process (`J = −∂ŷ/∂θ · ∂θ/∂z`); None when
/// a record's channel is not an accelerometer, the FMU would refuse the values, or the modes are
/// not distinct.
pub(super) fn linear_normals(fit: &LinearFit, target: &Target, z: &[f64]) -> Option<ModelNormals> {
    let values = target.values(z);
    if values.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let scale = prior_scales(target, &values);
    let mut r = Vec::with_capacity(target.rows());
    let mut blocks = Vec::new();
    for record in &target.records {
        let names: Vec<&str> = record.channels.iter().map(|c| c.name.as_str()).collect();
        let floors = fit.floors(&names)?;
        let measured: Vec<&[f64]> = record.channels.iter().map(|c| c.values).collect();
        let normals = fit.normals(&values, record.data, &floors, &measured, &record.used)?;
        for ((c, predicted), (m, v)) in record
            .channels
            .iter()
            .zip(&normals.predictions)
            .zip(normals.blocks)
        {
            r.extend(record.used.iter().map(|&k| c.values[k] - predicted[k]));
            let jtj =
                DMatrix::from_fn(m.nrows(), m.ncols(), |a, b| scale[a] * m[(a, b)] * scale[b]);
            let jtr = DVector::from_fn(v.len(), |a, _| -scale[a] * v[a]);
            blocks.push((jtj, jtr));
        }
    }
    Some(ModelNormals { r, blocks })
}

/// `∂u_j/∂z_j` at the values `u`: the prior's scale, times the value where the prior is on the
/// log.
pub(super) fn prior_scales(target: &Target, values: &[f64]) -> Vec<f64> {
    target
        .priors
        .iter()
        .zip(values)
        .map(|(prior, value)| match prior.space {
            Space::Linear => prior.sd(),
            Space::Log => prior.sd() * value,
        })
        .collect()
}

/// The sum of squares of every block (record, floor) of `r`.
pub(super) fn sse_per_block(r: &[f64], blocks: &[(usize, usize)]) -> Vec<f64> {
    blocks
        .iter()
        .map(|&(a, n)| r[a..a + n].iter().map(|x| x * x).sum())
        .collect()
}
impl<'a> Target<'a> {
    /// The calibration's target: the records, the calibrated parameters (`vrs`, with their
    /// `priors`), the component's other parameters as they are, and the FMU's sensitivities when
    /// every channel has them.
    pub(super) fn new(
        fmu: &'a Fmu,
        component: &Component,
        setup: &CalibrationSetup,
        records: Vec<RecordTarget<'a>>,
        vrs: Vec<u32>,
        priors: Vec<Prior>,
    ) -> Self {
        let mut base = component.parameters.clone();
        for name in &setup.parameters {
            base.remove(name);
        }
        let linear = LinearFit::new(&fmu.path, &base, &setup.parameters);
        let mut target = Target {
            fmu,
            base,
            records,
            vrs,
            priors,
            noise_var: setup.noise_log_variance,
            budget: setup.simulations_per_start.max(1),
            sensitivity: Sensitivity::find(fmu),
            linear,
            columns_threads: 1,
        };
        if !target.sensitive() {
            target.sensitivity = None;
        }
        target
    }
}
