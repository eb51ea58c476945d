//! Shared pieces of the cross-crate integration tests: where the workspace and its files are, a
//! reader for the force column of a measurement CSV, the one reference way to drive the
//! in-process shear model (`fmu_shear::ShearModel`) over a record, and the comparison of two
//! acceleration histories.
//!
//! The driving convention (see `tests/golden/README.md`): at each sample time `t_k = k·h` the
//! input is set, the outputs are read, then the model steps to `t_{k+1}`, except after the last
//! sample. N samples give N output rows and N − 1 steps.

use std::path::{Path, PathBuf};

use fmu_shear::model::RampInput;
use fmu_shear::ShearModel;

/// Sampling rate of the example records, Hz.
pub const SAMPLE_RATE_HZ: f64 = 51.2;

/// Communication step of the example records: 1/51.2 s = 0.01953125 s, exact in binary, so
/// `k as f64 * STEP` is the exact sample time for every k of a record.
pub const STEP: f64 = 1.0 / SAMPLE_RATE_HZ;

/// The workspace root (the parent of this crate's directory).
pub fn workspace_root() -> PathBuf {
    let manifest_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest_dir.parent().unwrap_or(manifest_dir).to_path_buf()
}

/// A bundled example record, e.g. `dataset("dataset1.csv")`.
pub fn dataset(file_name: &str) -> PathBuf {
    workspace_root().join("data").join(file_name)
}

/// The `time` and `force` columns of a measurement CSV (header `time,force,acc1,acc2,acc3`;
/// columns are found by name, extra columns are ignored).
#[derive(Clone, Debug)]
pub struct ForceRecord {
    pub time: Vec<f64>,
    pub force: Vec<f64>,
}

/// Read the force record of a measurement CSV. Errors name the file, the line and the problem.
pub fn read_force(path: &Path) -> Result<ForceRecord, String> {
    let columns = read_columns(path, &["time", "force"])?;
    let [time, force] = columns;
    if time.is_empty() {
        return Err(format!("{}: no data rows", path.display()));
    }
    Ok(ForceRecord { time, force })
}

/// Read named columns of a CSV with a header line as `f64`, in the order asked for.
pub fn read_columns<const N: usize>(
    path: &Path,
    names: &[&str; N],
) -> Result<[Vec<f64>; N], String> {
    let file = path.display();
    let mut reader = csv::Reader::from_path(path).map_err(|e| format!("{file}: {e}"))?;
    let header = reader
        .headers()
        .map_err(|e| format!("{file}: header: {e}"))?
        .clone();
    let mut index = [0usize; N];
    for (slot, name) in index.iter_mut().zip(names) {
        *slot = header
            .iter()
            .position(|h| h.trim() == *name)
            .ok_or_else(|| {
                format!(
                    "{file}: line 1: no column `{name}` in header {:?}",
                    header.iter().collect::<Vec<_>>()
                )
            })?;
    }
    let mut columns: [Vec<f64>; N] = std::array::from_fn(|_| Vec::new());
    for (row, record) in reader.records().enumerate() {
        let line = row + 2;
        let record = record.map_err(|e| format!("{file}: line {line}: {e}"))?;
        for ((column, &i), name) in columns.iter_mut().zip(&index).zip(names) {
            let text = record
                .get(i)
                .ok_or_else(|| format!("{file}: line {line}: missing `{name}`"))?;
            let value: f64 = text
                .trim()
                .parse()
                .map_err(|e| format!("{file}: line {line}: `{name}` = {text:?}: {e}"))?;
            if !value.is_finite() {
                return Err(format!("{file}: line {line}: `{name}` is {value}"));
            }
            column.push(value);
        }
    }
    Ok(columns)
}

/// How the force is presented to the model over each communication step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputConvention {
    /// First-order interpolation: over `[t_k, t_{k+1}]` the force is `F_k + s_k·(t − t_k)` with
    /// `s_k = (F_{k+1} − F_k)/h`. This is the golden's convention; an FMI master reaches it with
    /// `fmi2SetReal(force, F_k)` and `fmi2SetRealInputDerivatives(force, order 1, s_k)`.
    PiecewiseLinear,
    /// Values only: the force is held at `F_k` over the step (slope zero), what an FMI master
    /// gets when it calls `fmi2SetReal` and never `fmi2SetRealInputDerivatives`.
    ZeroOrderHold,
}

/// Drive `model` over the force samples `force` with communication step `step` and return the
/// floor accelerations `[acc1, acc2, acc3]` at every sample time: for each k the input is set
/// at `t_k`, the accelerations are read, then the model advances to `t_{k+1}` (not after the
/// last sample). The control force is left as the model has it.
pub fn simulate_accelerations(
    mut model: ShearModel,
    force: &[f64],
    step: f64,
    convention: InputConvention,
) -> Vec<[f64; 3]> {
    let mut accelerations = Vec::with_capacity(force.len());
    for (k, &value) in force.iter().enumerate() {
        let next = force.get(k + 1);
        let slope = match (convention, next) {
            (InputConvention::PiecewiseLinear, Some(&next)) => (next - value) / step,
            _ => 0.0,
        };
        model.force = RampInput { value, slope };
        let net_input = model.force.value - model.control_force.value;
        let mut acc = [0.0; 3];
        model.accelerations_into(
            &model.displacement,
            &model.velocity,
            net_input,
            0.0,
            &mut acc,
        );
        accelerations.push(acc);
        if next.is_some() {
            model.advance(step);
        }
    }
    accelerations
}

/// Agreement of one signal with a reference signal.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Agreement {
    /// `max_k |a_k − b_k|`.
    pub max_abs: f64,
    /// `max_k |a_k − b_k| / max_k |b_k|`: the difference relative to the reference's amplitude.
    pub relative_to_max_abs: f64,
    /// Number of samples whose bits differ.
    pub differing_samples: usize,
}

/// Per-floor agreement of `actual` with `reference` (same length required).
pub fn agreement(actual: &[[f64; 3]], reference: &[[f64; 3]]) -> Result<[Agreement; 3], String> {
    if actual.len() != reference.len() {
        return Err(format!(
            "{} samples against {} in the reference",
            actual.len(),
            reference.len()
        ));
    }
    Ok(std::array::from_fn(|floor| {
        let mut max_abs = 0.0f64;
        let mut amplitude = 0.0f64;
        let mut differing_samples = 0;
        for (a, b) in actual.iter().zip(reference) {
            max_abs = max_abs.max((a[floor] - b[floor]).abs());
            amplitude = amplitude.max(b[floor].abs());
            differing_samples += usize::from(a[floor].to_bits() != b[floor].to_bits());
        }
        let relative_to_max_abs = if amplitude > 0.0 {
            max_abs / amplitude
        } else {
            max_abs
        };
        Agreement {
            max_abs,
            relative_to_max_abs,
            differing_samples,
        }
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_step_is_exact_in_binary() {
        assert_eq!(STEP, 0.01953125);
        assert_eq!(1023.0 * STEP, 19.98046875);
    }

    #[test]
    fn the_example_record_is_read_by_column_name() {
        let record = read_force(&dataset("dataset1.csv")).expect("dataset1.csv is readable");
        assert_eq!(record.force.len(), 1024);
        assert_eq!(record.time[0], 0.0);
        assert_eq!(record.force[0], -0.00666308311);
    }

    #[test]
    fn the_two_conventions_share_the_first_sample_and_then_part() {
        let force = [0.0, 1.0, -1.0, 0.5];
        let run = |c| {
            simulate_accelerations(
                ShearModel::new(Default::default(), Default::default()),
                &force,
                STEP,
                c,
            )
        };
        let (ramp, hold) = (
            run(InputConvention::PiecewiseLinear),
            run(InputConvention::ZeroOrderHold),
        );
        assert_eq!(ramp.len(), 4);
        assert_eq!(ramp[0], hold[0]);
        assert!(ramp[1][0] != hold[1][0]);
    }
}
