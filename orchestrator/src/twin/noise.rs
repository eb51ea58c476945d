//! The measurement noise a calibrated twin keeps: one variance per measured channel, in the
//! channel's SI unit squared.
//!
//! In the twin's `resources/twin.ssv` an accelerometer's variance is `noise_variance{i}` (floor
//! i: the name the paper rig's twins have always used, so their archives are unchanged) and any
//! other channel's `noise_variance.{channel}` (`noise_variance.vel2`, `noise_variance.disp5`).

use std::collections::BTreeMap;

use structure::channel::{Channel, Quantity};

use super::ParameterValue;

const PREFIX: &str = "noise_variance";

/// Noise variance per channel, in the order the channels were first measured.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct NoiseVariances(Vec<(Channel, f64)>);

impl NoiseVariances {
    /// From channels and their variances; a channel given twice keeps its first value.
    pub fn new(pairs: impl IntoIterator<Item = (Channel, f64)>) -> NoiseVariances {
        let mut out = NoiseVariances::default();
        for (channel, v) in pairs {
            out.insert_first(channel, v);
        }
        out
    }

    /// Floors 1..=n's accelerometers, in order (the paper rig's `[acc1, acc2, acc3]`).
    pub fn of_floors(values: &[f64]) -> NoiseVariances {
        NoiseVariances::new(
            values
                .iter()
                .enumerate()
                .map(|(f, v)| (accelerometer(f + 1), *v)),
        )
    }

    /// Set `channel`'s variance unless it has one.
    pub fn insert_first(&mut self, channel: Channel, variance: f64) {
        if self.get(channel).is_none() {
            self.0.push((channel, variance));
        }
    }

    pub fn get(&self, channel: Channel) -> Option<f64> {
        self.0.iter().find(|(c, _)| *c == channel).map(|(_, v)| *v)
    }

    /// Every channel's variance, in order.
    pub fn iter(&self) -> impl Iterator<Item = (Channel, f64)> + '_ {
        self.0.iter().copied()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The variances of floors 1..=n's accelerometers, when the twin has each of them.
    pub fn floors(&self, n: usize) -> Option<Vec<f64>> {
        (1..=n).map(|f| self.get(accelerometer(f))).collect()
    }

    /// The twin.ssv parameter name of `channel`'s variance.
    pub fn parameter_name(channel: Channel) -> String {
        match channel {
            Channel::Response {
                quantity: Quantity::Acceleration,
                floor,
            } => format!("{PREFIX}{floor}"),
            other => format!("{PREFIX}.{}", other.name()),
        }
    }

    /// The channel a twin.ssv parameter names, if it is a noise variance.
    pub fn channel_of(parameter: &str) -> Option<Result<Channel, String>> {
        let rest = parameter.strip_prefix(PREFIX)?;
        let channel = if let Some(name) = rest.strip_prefix('.') {
            Channel::parse(name)
        } else {
            rest.parse::<usize>()
                .ok()
                .filter(|f| *f >= 1)
                .map(accelerometer)
        };
        Some(channel.ok_or_else(|| format!("'{parameter}' names no measured channel")))
    }

    /// The variances as twin.ssv parameters.
    pub fn parameters(&self) -> BTreeMap<String, ParameterValue> {
        self.0
            .iter()
            .map(|(c, v)| (Self::parameter_name(*c), ParameterValue::Real(*v)))
            .collect()
    }

    /// The variances among twin.ssv's parameters (None when there are none); a value that is
    /// not a positive real, or a name that is no channel, is an error naming it.
    pub fn from_parameters(
        values: &BTreeMap<String, ParameterValue>,
    ) -> Result<Option<NoiseVariances>, String> {
        let mut found: Vec<(Channel, f64)> = Vec::new();
        for (name, value) in values {
            let Some(channel) = Self::channel_of(name) else {
                continue;
            };
            let channel = channel?;
            match value {
                ParameterValue::Real(x) if *x > 0.0 && x.is_finite() => found.push((channel, *x)),
                other => return Err(format!("{name} = {other} is not a positive real")),
            }
        }
        if found.is_empty() {
            return Ok(None);
        }
        // Accelerometers by floor, then the others by name: the order the SSV lists them in
        // does not matter to the twin.
        found.sort_by_key(|(c, _)| {
            (
                c.quantity() != Quantity::Acceleration,
                c.name().len(),
                c.name(),
            )
        });
        Ok(Some(NoiseVariances(found)))
    }
}

fn accelerometer(floor: usize) -> Channel {
    Channel::Response {
        quantity: Quantity::Acceleration,
        floor,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_paper_rigs_names_read_and_write_as_before_and_other_channels_by_name() {
        let vel2 = Channel::parse("vel2").unwrap();
        let mut n = NoiseVariances::of_floors(&[1e-4, 2e-4, 3e-4]);
        n.insert_first(vel2, 5e-6);
        let p = n.parameters();
        let names: Vec<&str> = p.keys().map(String::as_str).collect();
        assert_eq!(
            names,
            [
                "noise_variance.vel2",
                "noise_variance1",
                "noise_variance2",
                "noise_variance3"
            ]
        );
        let back = NoiseVariances::from_parameters(&p).unwrap().unwrap();
        assert_eq!(back.floors(3), Some(vec![1e-4, 2e-4, 3e-4]));
        assert_eq!(back.get(vel2), Some(5e-6));
        assert_eq!(back.floors(4), None);
    }

    #[test]
    fn a_bad_name_or_value_is_named() {
        let mut p = BTreeMap::new();
        p.insert(
            "noise_variance.speed2".to_string(),
            ParameterValue::Real(1.0),
        );
        let e = NoiseVariances::from_parameters(&p).unwrap_err();
        assert!(e.contains("noise_variance.speed2"), "{e}");
        let mut p = BTreeMap::new();
        p.insert("noise_variance2".to_string(), ParameterValue::Real(-1.0));
        let e = NoiseVariances::from_parameters(&p).unwrap_err();
        assert!(e.contains("noise_variance2 = "), "{e}");
        assert_eq!(NoiseVariances::from_parameters(&BTreeMap::new()), Ok(None));
    }
}
