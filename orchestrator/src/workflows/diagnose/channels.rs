//! The record's measured channels as a diagnosis reads them (name, floor, quantity, values),
//! what a physics run predicts for each, and the NMSE per channel every stage scores with.

use structure::channel::{Channel, Quantity};

use super::physics::PhysicsRun;
use super::{DiagnoseError, Result, Sensing};
use crate::evaluation::stats::nmse;
use crate::twin::data::Measurement;

/// The measured channels a diagnosis reads, in the record's order: each one's name, floor,
/// quantity and values (SI). Accelerometers, velocity and displacement sensors alike: each
/// channel is predicted, fitted and scored in its own quantity; only the localisation, which
/// reads forces, takes the residual as an acceleration ([`Channels::residual_acceleration`]).
/// A floor the structure lacks is refused by name.
#[derive(Clone, Debug)]
pub(crate) struct Channels {
    pub names: Vec<String>,
    /// Each channel's floor, from 0.
    pub floors: Vec<usize>,
    /// Each channel's quantity: acceleration (absolute), velocity or displacement (relative
    /// to the ground), as the record's `acc<i>`, `vel<i>`, `disp<i>` and the shear FMU's
    /// outputs of those names.
    pub quantities: Vec<Quantity>,
    pub measured: Vec<Vec<f64>>,
}

impl Channels {
    pub fn of(data: &Measurement, storeys: usize) -> Result<Channels> {
        let mut out = Channels {
            names: Vec::new(),
            floors: Vec::new(),
            quantities: Vec::new(),
            measured: Vec::new(),
        };
        for signal in &data.responses {
            let name = signal.channel.name();
            let (quantity, floor) = match signal.channel {
                Channel::Response {
                    quantity:
                        q @ (Quantity::Acceleration | Quantity::Velocity | Quantity::Displacement),
                    floor,
                } => (q, floor),
                _ => {
                    return Err(DiagnoseError::Setup(format!(
                        "{}: column '{name}': a diagnosis reads responses (acc<i>, vel<i>, \
                         disp<i>); the record has {}",
                        data.path.display(),
                        data.channel_names().join(", ")
                    )))
                }
            };
            if !(1..=storeys).contains(&floor) {
                return Err(DiagnoseError::Setup(format!(
                    "{}: column '{name}': the twin's building has floors 1 to {storeys}",
                    data.path.display()
                )));
            }
            out.names.push(name);
            out.floors.push(floor - 1);
            out.quantities.push(quantity);
            out.measured.push(signal.values.clone());
        }
        if out.names.is_empty() {
            return Err(DiagnoseError::Setup(format!(
                "{}: no response channel (acc<i>, vel<i>, disp<i>) to diagnose",
                data.path.display()
            )));
        }
        Ok(out)
    }

    /// The (floor, quantity) of each channel: where and what a sensitivity is read at.
    pub fn sensors(&self) -> Vec<(usize, Quantity)> {
        self.floors
            .iter()
            .copied()
            .zip(self.quantities.iter().copied())
            .collect()
    }

    /// How each channel enters the diagnosis (its visibility is measured at the end).
    pub fn sensing(&self) -> Vec<Sensing> {
        self.names
            .iter()
            .zip(&self.quantities)
            .map(|(name, q)| {
                let (quantity, localisation) = match q {
                    Quantity::Velocity => ("velocity", "differentiated once"),
                    Quantity::Displacement => ("displacement", "differentiated twice"),
                    _ => ("acceleration", "as measured"),
                };
                Sensing {
                    channel: name.clone(),
                    quantity: quantity.into(),
                    localisation: localisation.into(),
                    visibility: None,
                }
            })
            .collect()
    }

    /// Per channel, what the physics run `run` gives at its floor in its quantity.
    pub(super) fn predicted(&self, run: &PhysicsRun) -> Vec<Vec<f64>> {
        self.sensors()
            .into_iter()
            .map(|(f, q)| run.at(f, q).to_vec())
            .collect()
    }

    /// Per channel, measured minus what the physics run `run` gives, in the channel's quantity.
    pub(super) fn residuals(&self, run: &PhysicsRun) -> Vec<Vec<f64>> {
        self.measured
            .iter()
            .zip(self.predicted(run))
            .map(|(measured, predicted)| {
                measured
                    .iter()
                    .zip(&predicted)
                    .map(|(m, p)| m - p)
                    .collect()
            })
            .collect()
    }

    /// Channel `c`'s residual (measured − `predicted`) as an acceleration: as it is for an
    /// accelerometer, differentiated once (velocity) or twice (displacement) by central
    /// differences (one-sided at the ends) on the sampling interval `dt`. Differencing
    /// amplifies the noise in proportion to the frequency, so such a channel's localisation
    /// is noisier at high frequency; the fits never use it.
    pub fn residual_acceleration(&self, c: usize, predicted: &[f64], dt: f64) -> Vec<f64> {
        let residual: Vec<f64> = self.measured[c]
            .iter()
            .zip(predicted)
            .map(|(m, p)| m - p)
            .collect();
        match self.quantities[c] {
            Quantity::Velocity => derivative(&residual, dt),
            Quantity::Displacement => derivative(&derivative(&residual, dt), dt),
            _ => residual,
        }
    }

    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// The index of the channel named `name` (one of this record's).
    pub fn index(&self, name: &str) -> usize {
        self.names.iter().position(|n| n == name).unwrap_or(0)
    }

    /// NMSE per channel of `predicted` (per channel) over the samples `idx`.
    pub fn nmse_on(&self, predicted: &[Vec<f64>], idx: &[usize]) -> Vec<f64> {
        nmse_on(&self.measured, predicted, idx)
    }
}

/// The derivative of a sampled series by central differences, one-sided at the ends.
pub(super) fn derivative(x: &[f64], dt: f64) -> Vec<f64> {
    let n = x.len();
    if n < 2 {
        return vec![0.0; n];
    }
    (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
            (x[b] - x[a]) / ((b - a) as f64 * dt)
        })
        .collect()
}

/// NMSE per channel over the samples `idx`.
pub(super) fn nmse_on(measured: &[Vec<f64>], predicted: &[Vec<f64>], idx: &[usize]) -> Vec<f64> {
    measured
        .iter()
        .zip(predicted)
        .map(|(measured, predicted)| {
            let y: Vec<f64> = idx.iter().map(|&k| measured[k]).collect();
            let p: Vec<f64> = idx.iter().map(|&k| predicted[k]).collect();
            nmse(&y, &p)
        })
        .collect()
}

pub(super) use crate::evaluation::stats::worst;
