//! What an identification reports: each channel's FRF, the responses' spectrum, each
//! method's modes (with their floors' shapes) and what it set aside, the record's whole result.

use serde::Serialize;
use structure::channel::{Channel, Quantity};

use super::super::pair::ObservedMode;
use super::{IdentifyOptions, RunView};
use numerics::modal::spectral::Frf;
use numerics::modal::stabilisation::{IdentifiedMode, RejectedMode, StabilisationDiagram};
use numerics::modal::Complex;

/// One response channel's FRF to the excitation.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelFrf {
    pub channel: String,
    /// The FRF's unit: the channel's SI unit per the excitation's.
    pub unit: String,
    /// Per frequency, `[re, im]`.
    pub response: Vec<Complex>,
    pub coherence: Vec<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct FrfReport {
    pub segment_length: usize,
    pub segments: usize,
    /// Hz.
    pub frequencies: Vec<f64>,
    pub channels: Vec<ChannelFrf>,
}

/// The sum of the response channels' PSDs (each in its SI unit² / Hz): the spectrum the
/// stabilisation diagram is drawn over.
#[derive(Debug, Clone, Serialize)]
pub struct SpectrumReport {
    pub frequencies: Vec<f64>,
    pub total: Vec<f64>,
}

/// A mode identified from the record.
#[derive(Debug, Clone, Serialize)]
pub struct RecordMode {
    #[serde(flatten)]
    pub identified: IdentifiedMode,
    /// The shape at [`RecordModes::floors`] as displacements (each channel's component divided
    /// by `λ²` for an accelerometer, `λ` for a velocity sensor), largest component 1.
    pub displacement_shape: Vec<Complex>,
}

/// One method's diagram and modes.
#[derive(Debug, Clone, Serialize)]
pub struct MethodModes {
    /// `SSI-COV` or `LSCF`.
    pub method: &'static str,
    /// Hz, the band fitted (LSCF).
    pub band: Option<(f64, f64)>,
    pub diagram: StabilisationDiagram,
    pub modes: Vec<RecordMode>,
    /// Modes the diagram holds that are not the structure's, each with its reason.
    pub rejected: Vec<RejectedMode>,
}

/// The non-parametric method's modes (FDD's peaks, EFDD's frequencies and damping), a
/// cross-check of the parametric ones.
#[derive(Debug, Clone, Serialize)]
pub struct FddModes {
    /// `FDD/EFDD`.
    pub method: &'static str,
    /// Hz, the band peaks were picked in.
    pub band: (f64, f64),
    /// The first singular value of the outputs' spectral matrix, at the spectrum's frequencies.
    pub first_singular: Vec<f64>,
    pub modes: Vec<RecordMode>,
    pub rejected: Vec<RejectedMode>,
}

/// Everything identified from a record.
#[derive(Debug, Clone, Serialize)]
pub struct RecordModes {
    pub records: Vec<String>,
    /// s.
    pub dt: f64,
    /// Samples per run.
    pub samples: Vec<usize>,
    pub excitation: String,
    /// The response channels, in the order of the shapes' components.
    pub channels: Vec<String>,
    /// The floors (1-based) of [`RecordMode::displacement_shape`]: the first channel of each
    /// measured floor, by floor.
    pub floors: Vec<usize>,
    pub frf: Option<FrfReport>,
    pub spectrum: SpectrumReport,
    pub ssi: MethodModes,
    pub input_output: Option<MethodModes>,
    pub fdd: FddModes,
    /// Every method's modes side by side.
    pub verdicts: Vec<ModeVerdict>,
    pub options: IdentifyOptions,
}

impl RecordModes {
    /// The modes to compare with a twin's: the input–output method's when it ran (an FRF
    /// fit is the more accurate), otherwise SSI-COV's; shapes at [`RecordModes::floors`].
    pub fn observed(&self) -> Vec<ObservedMode> {
        let method = self.input_output.as_ref().unwrap_or(&self.ssi);
        method
            .modes
            .iter()
            .map(|m| ObservedMode {
                frequency: m.identified.frequency,
                frequency_sd: Some(m.identified.frequency_sd),
                damping: m.identified.damping,
                damping_sd: Some(m.identified.damping_sd),
                shape: m.displacement_shape.clone(),
            })
            .collect()
    }
}

/// The FRF's report: each channel's response and coherence, in its unit per the excitation's.
pub(super) fn frf_report(
    frf: Frf,
    channels: &[Channel],
    first: &RunView<'_>,
    segment_length: usize,
) -> FrfReport {
    let excitation_unit = first
        .excitation
        .map_or("?", |e| e.channel.quantity().si().symbol());
    FrfReport {
        segment_length,
        segments: frf.segments,
        channels: channels
            .iter()
            .zip(frf.response.iter().zip(&frf.coherence))
            .map(|(channel, (h, c))| ChannelFrf {
                channel: channel.name(),
                unit: format!("({})/{excitation_unit}", channel.quantity().si().symbol()),
                response: h.clone(),
                coherence: c.clone(),
            })
            .collect(),
        frequencies: frf.frequencies,
    }
}

/// Per measured floor (ascending), its first channel's index and the power of `λ` that
/// turns that channel's shape component into a displacement.
pub(super) fn shape_floors(channels: &[Channel]) -> Vec<(usize, (usize, i32))> {
    let mut floors: Vec<(usize, (usize, i32))> = Vec::new();
    for (index, channel) in channels.iter().enumerate() {
        if let Channel::Response { quantity, floor } = channel {
            if floors.iter().any(|(f, _)| f == floor) {
                continue;
            }
            let power = match quantity {
                Quantity::Acceleration => 2,
                Quantity::Velocity => 1,
                Quantity::Displacement | Quantity::Time | Quantity::Force => 0,
            };
            floors.push((*floor, (index, power)));
        }
    }
    floors.sort_by_key(|(f, _)| *f);
    floors
}

pub(super) fn record_modes(
    modes: Vec<IdentifiedMode>,
    floors: &[(usize, (usize, i32))],
) -> Vec<RecordMode> {
    modes
        .into_iter()
        .map(|identified| {
            let w = 2.0 * std::f64::consts::PI * identified.frequency;
            let z = identified.damping;
            let lambda = Complex::new(-z * w, w * (1.0 - z * z).max(0.0).sqrt());
            let shape: Vec<Complex> = floors
                .iter()
                .map(|(_, (index, power))| identified.shape[*index] / lambda.powi(*power))
                .collect();
            RecordMode {
                displacement_shape: numerics::modal::stabilisation::normalised(shape),
                identified,
            }
        })
        .collect()
}

/// The methods' verdicts side by side ([`super::verdicts`]): one method's answer for a mode.
#[derive(Debug, Clone, Serialize)]
pub struct MethodVerdict {
    pub method: &'static str,
    /// Hz.
    pub frequency: f64,
    pub damping: f64,
    pub damping_sd: f64,
}

/// The MAC between two methods' shapes of one mode (when their shapes are at the same floors).
#[derive(Debug, Clone, Serialize)]
pub struct ShapeAgreement {
    pub methods: (&'static str, &'static str),
    pub mac: f64,
}

/// One row of the verdicts' table.
#[derive(Debug, Clone, Serialize)]
pub struct ModeVerdict {
    /// Hz, the mean of the methods' frequencies.
    pub frequency: f64,
    pub found_by: Vec<MethodVerdict>,
    pub macs: Vec<ShapeAgreement>,
    /// Found by one method only (of more than one that ran).
    pub one_method_only: bool,
}
