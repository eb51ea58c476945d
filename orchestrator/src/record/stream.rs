//! A record one CSV line at a time, as a live stream gives it (`twin watch`): the header line
//! gives the columns' positions, each later line one sample.

use super::read::parse_value;
use super::REQUIRED_COLUMNS;

/// The columns of a stream without a header line of its own (an MQTT message).
pub const DEFAULT_HEADER: &str = "time,force,acc1,acc2,acc3";

/// Column positions of a stream's header line.
#[derive(Debug, Clone)]
pub struct LineLayout {
    width: usize,
    time: usize,
    force: usize,
    acc: [usize; 3],
}

impl LineLayout {
    /// The layout of a header line; Err says which required column it lacks.
    pub fn parse(line: &str) -> Result<Self, String> {
        let names: Vec<&str> = line.split(',').map(str::trim).collect();
        let at = |name: &str| {
            names.iter().position(|n| *n == name).ok_or_else(|| {
                format!(
                    "'{line}' has no column '{name}' (it must have {})",
                    REQUIRED_COLUMNS.join(",")
                )
            })
        };
        Ok(LineLayout {
            width: names.len(),
            time: at("time")?,
            force: at("force")?,
            acc: [at("acc1")?, at("acc2")?, at("acc3")?],
        })
    }

    /// (time, force, accelerations), or why the line is not a sample.
    pub fn sample(&self, line: &str) -> Result<(f64, f64, [f64; 3]), String> {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != self.width {
            return Err(format!(
                "{} fields, the header has {}",
                fields.len(),
                self.width
            ));
        }
        let value = |i: usize, name: &str| parse_value(name, fields[i]);
        Ok((
            value(self.time, "time")?,
            value(self.force, "force")?,
            [
                value(self.acc[0], "acc1")?,
                value(self.acc[1], "acc2")?,
                value(self.acc[2], "acc3")?,
            ],
        ))
    }
}

/// The sampling interval from one step of printed times: the coarsest round rate (1, 0.1,
/// 0.01 or 0.001 Hz) whose interval is within the times' 1 µs printing of it, else the step.
pub fn nominal_step(step: f64) -> f64 {
    for resolution in [1.0, 0.1, 0.01, 0.001] {
        let rate = (1.0 / step / resolution).round() * resolution;
        if rate > 0.0 && (1.0 / rate - step).abs() <= 2e-6 {
            return 1.0 / rate;
        }
    }
    step
}
