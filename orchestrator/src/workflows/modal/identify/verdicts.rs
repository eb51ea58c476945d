//! The methods' verdicts side by side: the modes of every method (LSCF, SSI-COV, FDD/EFDD)
//! grouped by frequency into one table — per mode, the methods that found it with their
//! frequencies and damping, the MAC between their shapes, and whether one method alone found
//! it (a mode to look at twice).

pub use super::report::{MethodVerdict, ModeVerdict, ShapeAgreement};
use super::RecordMode;
use numerics::modal::mac;

/// Two methods' modes within this relative frequency of each other are one mode.
pub const SAME_MODE: f64 = 0.02;

/// The table of `methods` (each its name and modes), by frequency. A mode joins the row of
/// the modes below it when it is within [`SAME_MODE`] of the row's highest (each method once
/// a row, so a row spans at most twice that): on the paper rig's dataset2 SSI-COV's 5.9052
/// and FDD/EFDD's 6.0306 Hz are 2.1 % apart, each within 1.4 % of LSCF's 5.9635 Hz between
/// them, and measured from the row's lowest FDD's made a row of its own, one method only.
pub fn verdicts(methods: &[(&'static str, &[RecordMode])]) -> Vec<ModeVerdict> {
    let mut all: Vec<(usize, &RecordMode)> = methods
        .iter()
        .enumerate()
        .flat_map(|(k, (_, modes))| modes.iter().map(move |m| (k, m)))
        .collect();
    all.sort_by(|a, b| {
        a.1.identified
            .frequency
            .total_cmp(&b.1.identified.frequency)
    });
    let mut rows: Vec<Vec<(usize, &RecordMode)>> = Vec::new();
    for (k, m) in all {
        match rows.last_mut() {
            Some(row)
                if (m.identified.frequency / row[row.len() - 1].1.identified.frequency - 1.0)
                    .abs()
                    <= SAME_MODE
                    && row.iter().all(|(other, _)| *other != k) =>
            {
                row.push((k, m))
            }
            _ => rows.push(vec![(k, m)]),
        }
    }
    rows.into_iter().map(|row| verdict(methods, &row)).collect()
}

fn verdict(methods: &[(&'static str, &[RecordMode])], row: &[(usize, &RecordMode)]) -> ModeVerdict {
    let found_by: Vec<MethodVerdict> = row
        .iter()
        .map(|(k, m)| MethodVerdict {
            method: methods[*k].0,
            frequency: m.identified.frequency,
            damping: m.identified.damping,
            damping_sd: m.identified.damping_sd,
        })
        .collect();
    let mut macs = Vec::new();
    for (i, (a, ma)) in row.iter().enumerate() {
        for (b, mb) in &row[i + 1..] {
            if ma.displacement_shape.len() == mb.displacement_shape.len() {
                macs.push(ShapeAgreement {
                    methods: (methods[*a].0, methods[*b].0),
                    mac: mac(&ma.displacement_shape, &mb.displacement_shape),
                });
            }
        }
    }
    let ran = methods.len();
    ModeVerdict {
        frequency: found_by.iter().map(|v| v.frequency).sum::<f64>() / found_by.len() as f64,
        one_method_only: ran > 1 && found_by.len() == 1,
        found_by,
        macs,
    }
}
