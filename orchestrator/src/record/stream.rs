//! A record one CSV line at a time, as a live stream gives it (`twin watch`): the header line
//! gives the columns' positions, each later line one sample.

use ::structure::channel::{parse_header_field, ChannelError};

use super::read::parse_value;
use super::REQUIRED_COLUMNS;

/// The columns of a stream without a header line of its own (an MQTT message).
pub const DEFAULT_HEADER: &str = "time,force,acc1,acc2,acc3";

/// Column positions of a stream's header line, and each column's factor to SI (a header field
/// may carry its unit, `acc1 (g)`, as in a file).
#[derive(Debug, Clone)]
pub struct LineLayout {
    width: usize,
    time: (usize, f64),
    force: (usize, f64),
    acc: [(usize, f64); 3],
}

impl LineLayout {
    /// The layout of a header line; Err says which required column it lacks, or which field
    /// has a unit that is not its quantity's.
    pub fn parse(line: &str) -> Result<Self, String> {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let mut known = Vec::with_capacity(fields.len());
        for field in &fields {
            known.push(match parse_header_field(field) {
                Ok((channel, unit)) => Some((channel.name(), unit.to_si())),
                // Columns the stream does not use are passed over, as before units.
                Err(ChannelError::UnknownName(_)) => None,
                Err(e) => return Err(e.to_string()),
            });
        }
        let at = |name: &str| {
            known
                .iter()
                .position(|k| k.as_ref().is_some_and(|(n, _)| n == name))
                .map(|i| (i, known[i].as_ref().map_or(1.0, |k| k.1)))
                .ok_or_else(|| {
                    format!(
                        "'{line}' has no column '{name}' (it must have {})",
                        REQUIRED_COLUMNS.join(",")
                    )
                })
        };
        Ok(LineLayout {
            width: fields.len(),
            time: at("time")?,
            force: at("force")?,
            acc: [at("acc1")?, at("acc2")?, at("acc3")?],
        })
    }

    /// (time, force, accelerations) in SI, or why the line is not a sample.
    pub fn sample(&self, line: &str) -> Result<(f64, f64, [f64; 3]), String> {
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != self.width {
            return Err(format!(
                "{} fields, the header has {}",
                fields.len(),
                self.width
            ));
        }
        let value = |(i, factor): (usize, f64), name: &str| {
            parse_value(name, fields[i]).map(|v| if factor == 1.0 { v } else { v * factor })
        };
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stream_header_with_units_gives_samples_in_si() {
        let layout =
            LineLayout::parse("acc3,time,force (kN),acc1 (g),note,acc2 (mm/s2)").expect("layout");
        let (t, f, acc) = layout.sample("3, 0.5, 2, 1, x, 1000").expect("sample");
        assert_eq!((t, f), (0.5, 2000.0));
        assert_eq!(acc, [9.80665, 1.0, 3.0]);
        let e = LineLayout::parse("time,force,acc1,acc2").expect_err("no acc3");
        assert!(e.contains("'acc3'"), "{e}");
        let e = LineLayout::parse("time,force,acc1 (mm/s),acc2,acc3").expect_err("wrong unit");
        assert!(e.contains("acc1 (mm/s)"), "{e}");
    }
}
