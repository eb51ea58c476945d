//! Modes identified from a record (`twin modal --data`): the FRF of every response channel to
//! the measured excitation (H1, with its coherence), the modes by the input–output method
//! (LSCF with LSFD shapes) when the excitation was measured, and by the output-only one
//! (SSI-COV) always, each with its stabilisation diagram and the automatically chosen physical
//! modes. Any channels, units and excitation; several runs of one test average together.

mod band;
mod excitation;
mod input_output;
mod leaky;
mod orders;
mod peaks;
mod report;
mod roving;
mod runs;
mod shoulder;
mod split;
pub mod verdicts;

use serde::Serialize;
use structure::channel::Channel;

use crate::record::{AmbientRecord, Measurement, Signal};
use numerics::modal::fdd::{fdd, FddOptions};
use numerics::modal::lscf::Weighting;
use numerics::modal::spectral::{Run, Welch, MIN_SEGMENT};
use numerics::modal::ssi::{ssi_cov, SsiOptions};
use numerics::modal::stabilisation::{
    screen_by_peaks, screen_modes, RejectedMode, Rejection, ScreenOptions, SelectionOptions,
    StabilityTolerances,
};
use numerics::modal::IdentificationError;

use band::screen_options;
pub use band::{
    excited_band, fit_band, measured_band, BAND_COHERENCE, COHERENT_RUN, EXCITED_FRACTION,
    MEASURED_COHERENCE,
};
pub use excitation::{FORCE_PEAK, FORCE_PEAK_WIDTH};
use peaks::Peaks;
use report::{frf_report, record_modes, shape_floors};
pub use report::{
    ChannelFrf, FddModes, FrfReport, MethodModes, RecordMode, RecordModes, SpectrumReport,
};
use runs::{all_channels, check_runs, run_channels, RunView, Sampling, Signals};
pub use runs::{default_segment, evidence_segment, EVIDENCE_SEGMENTS, RESOLVING_SEGMENT};

#[derive(Debug, thiserror::Error)]
pub enum IdentifyError {
    #[error("{0}")]
    Options(String),
    #[error("{path}: {message}")]
    Record { path: String, message: String },
    #[error("{method} on {records}: {source}")]
    Method {
        method: &'static str,
        records: String,
        #[source]
        source: IdentificationError,
    },
}

/// What `twin modal --data` identifies, and how.
#[derive(Debug, Clone, Serialize)]
pub struct IdentifyOptions {
    /// Samples per Welch segment of the FRF and the spectrum; None: the largest power of two
    /// that gives [`DEFAULT_SEGMENTS`] half-overlapping segments in the shortest run.
    pub segment_length: Option<usize>,
    /// Hz, the band LSCF fits; None: from the first bin to [`DEFAULT_BAND_TOP`] of Nyquist.
    pub band: Option<(f64, f64)>,
    /// The largest model order of both methods (orders 2, 4, …) — for LSCF, the order its
    /// sweep goes to before it looks whether modes are still forming ([`LSCF_ORDER_STEP`],
    /// [`LSCF_ORDER_REACH`]).
    pub max_order: usize,
    /// Whether LSCF sweeps on past `max_order` while its highest order holds stable poles no
    /// mode is made of yet.
    pub extend_orders: bool,
    /// SSI-COV's block rows; None: SSI-COV's default for the channels and order.
    pub block_rows: Option<usize>,
    pub stability: StabilityTolerances,
    pub selection: SelectionOptions,
    /// What sets an identified mode aside as not the structure's (the excitation's band is
    /// filled in from the record's force).
    pub screen: ScreenOptions,
    /// How LSCF weights the FRF's bins.
    pub weighting: Weighting,
    /// Whether to run the input–output method when the excitation has power.
    pub input_output: bool,
}

/// Segments a default Welch segment length leaves in the shortest run (at least). Four, not
/// the twelve of earlier: a lab frame's 30 s runs at 500 Hz in twelve segments had 0.24 Hz
/// bins, ten times its first mode's half-power width (0.4 % at 3.17 Hz), and LSCF missed
/// that mode in two of three runs; in four (0.12 Hz) it finds it within 0.73 %. The FRF is
/// noisier, which the coherence weighting and the peak screen absorb.
pub const DEFAULT_SEGMENTS: usize = 4;
/// The default LSCF band's top, as a fraction of Nyquist (the anti-aliasing roll-off above).
pub const DEFAULT_BAND_TOP: f64 = 0.8;
/// The least coherence of the FRF near an FDD/EFDD peak, with the force measured (the issue's
/// bar for a peak an engineer reads off the FRF): FDD takes every maximum of the first
/// singular value, with no model order to tell noise by, and the parametric methods' 0.5
/// let a noise peak of the lab frame's single-channel 1–60 Hz run through (49.62 Hz).
pub const FDD_PEAK_COHERENCE: f64 = 0.7;
/// Orders LSCF's sweep goes on by, past [`IdentifyOptions::max_order`], while modes are still
/// forming at its highest order ([`forming_poles`]).
pub const LSCF_ORDER_STEP: usize = 20;
/// How far the sweep goes on: up to this many times [`IdentifyOptions::max_order`]. A z-domain
/// fit over a band much wider than where the modes are spends its orders on the empty part:
/// a seven-storey tower (0.93–8.66 Hz) fitted over 0.5–30 Hz had two of its seven modes at
/// order 40 and all seven at 80; ten storeys nine of ten at 120.
pub const LSCF_ORDER_REACH: usize = 3;

impl Default for IdentifyOptions {
    fn default() -> Self {
        IdentifyOptions {
            segment_length: None,
            band: None,
            max_order: 40,
            extend_orders: true,
            block_rows: None,
            stability: StabilityTolerances::default(),
            selection: SelectionOptions::default(),
            screen: ScreenOptions::default(),
            weighting: Weighting::default(),
            input_output: true,
        }
    }
}

impl IdentifyOptions {
    /// Checks the options on their own, before any record is read.
    pub fn validate(&self) -> Result<(), IdentifyError> {
        let bad = |m: String| Err(IdentifyError::Options(m));
        if let Some(segment) = self.segment_length {
            if segment < MIN_SEGMENT {
                return bad(format!(
                    "--segment {segment}: a Welch segment holds at least {MIN_SEGMENT} samples"
                ));
            }
        }
        if let Some((low, high)) = self.band {
            if !(low.is_finite() && high.is_finite() && low >= 0.0 && high > low) {
                return bad(format!(
                    "--band {low}:{high}: a band is LOW:HIGH Hz with 0 <= LOW < HIGH"
                ));
            }
        }
        if self.max_order < 2 || self.max_order % 2 != 0 {
            return bad(format!(
                "--max-order {}: an even model order of at least 2 (two per mode)",
                self.max_order
            ));
        }
        if self.block_rows == Some(0) || self.block_rows == Some(1) {
            return bad("--block-rows: at least 2".into());
        }
        self.stability
            .validate()
            .and_then(|()| self.selection.validate())
            .and_then(|()| self.screen.validate())
            .map_err(|e| IdentifyError::Options(e.to_string()))
    }

    fn ssi(&self) -> SsiOptions {
        SsiOptions {
            max_order: self.max_order,
            block_rows: self.block_rows,
            ..SsiOptions::default()
        }
    }
}

/// Identifies the modes of `runs` (one record, or several runs of one test).
pub fn identify(
    runs: &[Measurement],
    options: &IdentifyOptions,
) -> Result<RecordModes, IdentifyError> {
    let views: Vec<RunView<'_>> = runs
        .iter()
        .map(|r| RunView {
            path: &r.path,
            dt: r.dt,
            excitation: Some(&r.excitation),
            responses: &r.responses,
        })
        .collect();
    identify_runs(&views, options, |stage| stage.record_modes())
}

/// Identifies the modes of ambient records (responses only): SSI-COV alone, no FRF.
pub fn identify_ambient(
    runs: &[AmbientRecord],
    options: &IdentifyOptions,
) -> Result<RecordModes, IdentifyError> {
    let views: Vec<RunView<'_>> = runs
        .iter()
        .map(|r| RunView {
            path: &r.path,
            dt: r.dt,
            excitation: None,
            responses: &r.responses,
        })
        .collect();
    identify_runs(&views, options, |stage| stage.record_modes())
}

/// Identifies the modes of one stretch of a stream sampled every `dt` s (`twin watch
/// --track-modes`' window): SSI-COV's modes of its `responses`, chosen and screened as `twin
/// modal` chooses them for a record — with the stream's `excitation`, when measured, for the
/// force's band edge and its own peaks (one-channel shapes, one resonance, no peak in the
/// spectrum alike). Only what the watch tracks is computed: no input–output fit, whatever
/// `options` say, and no FDD/EFDD cross-check or verdicts (FDD/EFDD was 56 % of a window's
/// instructions).
pub fn identify_window(
    dt: f64,
    excitation: Option<&Signal>,
    responses: &[Signal],
    options: &IdentifyOptions,
) -> Result<MethodModes, IdentifyError> {
    let view = RunView {
        path: std::path::Path::new("the stream's window"),
        dt,
        excitation,
        responses,
    };
    let options = IdentifyOptions {
        input_output: false,
        ..options.clone()
    };
    identify_runs(&[view], &options, |stage| stage.output_only_modes())
}

/// Identifies the modes of `runs` (one test): their total spectrum, SSI-COV's modes, and with
/// a measured excitation the FRF and the input–output method's modes; `finish` takes them on
/// from there ([`Stage::record_modes`]: the force's own peaks set aside, FDD/EFDD's
/// cross-check, the verdicts).
fn identify_runs<T>(
    runs: &[RunView<'_>],
    options: &IdentifyOptions,
    finish: fn(Stage<'_>) -> Result<T, IdentifyError>,
) -> Result<T, IdentifyError> {
    options.validate()?;
    let roving = check_runs(runs)?;
    let first = &runs[0];
    let sampling = Sampling::of(runs, options)?;
    let everywhere = all_channels(runs);
    let signals = Signals::of(runs, &everywhere);
    let estimation = Estimation {
        welch: Welch::new(sampling.dt, sampling.segment_length)
            .map_err(sampling.method_err("the spectra"))?,
        spectral_runs: signals.runs(runs),
        per_channel: signals.per_channel(runs, &everywhere),
        run_channels: run_channels(runs, &everywhere),
        roving,
        options,
        sampling,
    };
    let spectrum = estimation.total_spectrum()?;
    let channels: Vec<Channel> = everywhere.iter().map(|(c, _)| *c).collect();
    let floors = shape_floors(&channels);
    let force_psd = estimation.force_spectrum(runs)?;
    let measured = match &force_psd {
        Some(psd) => Some((psd.as_slice(), estimation.measured_frf()?)),
        None => None,
    };
    let screen = screen_options(
        measured.as_ref().map(|(psd, frf)| (*psd, frf)),
        &spectrum.frequencies,
        options,
    );
    let ssi = estimation.output_only(first, &floors, &screen, Peaks::of_spectrum(&spectrum))?;
    let (frf, input_output, frf_peaks, force_peaks) = match measured {
        Some((force_psd, frf)) => {
            let peaks = screen.excited.map_or_else(Vec::new, |band| {
                excitation::force_peaks(&frf.frequencies, force_psd, band)
            });
            let whole = Peaks::of_frf(&frf);
            let (report, input_output, evidence) =
                estimation.with_force(frf, force_psd, first, &channels, &floors, &screen)?;
            (Some(report), input_output, evidence, Some((peaks, whole)))
        }
        None => (None, None, None, None),
    };
    finish(Stage {
        runs,
        estimation: &estimation,
        spectrum,
        channels,
        floors,
        screen,
        ssi,
        frf,
        input_output,
        frf_peaks,
        force_peaks,
    })
}

/// One test's spectra, FRF and parametric modes, before the force's own peaks are set aside
/// and before the non-parametric cross-check: what every identification shares.
struct Stage<'a> {
    runs: &'a [RunView<'a>],
    estimation: &'a Estimation<'a>,
    spectrum: SpectrumReport,
    channels: Vec<Channel>,
    floors: Vec<(usize, (usize, i32))>,
    screen: ScreenOptions,
    ssi: MethodModes,
    frf: Option<FrfReport>,
    input_output: Option<MethodModes>,
    /// The FRF a mode's peak is judged on (a single test, the force measured).
    frf_peaks: Option<Peaks>,
    /// With the force measured: its own spectral peaks, and the whole FRF's peaks.
    force_peaks: Option<(Vec<(f64, f64)>, Peaks)>,
}

impl Stage<'_> {
    /// SSI-COV's modes, a mode at the force's own peak set aside: what the watch tracks.
    fn output_only_modes(self) -> Result<MethodModes, IdentifyError> {
        let Stage {
            mut ssi,
            frf_peaks,
            force_peaks,
            ..
        } = self;
        if let Some((peaks, whole)) = &force_peaks {
            let frf = frf_peaks.as_ref().unwrap_or(whole);
            excitation::set_aside_excitation(&mut ssi.modes, &mut ssi.rejected, peaks, frf);
        }
        Ok(ssi)
    }

    /// Everything `twin modal --data` reports: the parametric modes and FDD/EFDD's, a mode at
    /// the force's own peak set aside in each, and the methods' verdicts side by side.
    fn record_modes(self) -> Result<RecordModes, IdentifyError> {
        let Stage {
            runs,
            estimation,
            spectrum,
            channels,
            floors,
            screen,
            mut ssi,
            frf,
            mut input_output,
            frf_peaks,
            force_peaks,
        } = self;
        let first = &runs[0];
        let fdd_band = input_output.as_ref().and_then(|m| m.band).unwrap_or((
            spectrum.frequencies.get(1).copied().unwrap_or(0.0),
            DEFAULT_BAND_TOP * estimation.sampling.nyquist,
        ));
        let fdd_evidence = frf_peaks
            .clone()
            .unwrap_or_else(|| Peaks::of_spectrum(&spectrum));
        let mut fdd = estimation.non_parametric(first, &floors, &screen, fdd_band, fdd_evidence)?;
        if let Some((peaks, whole)) = &force_peaks {
            let frf = frf_peaks.as_ref().unwrap_or(whole);
            let methods = input_output
                .iter_mut()
                .map(|m| (&mut m.modes, &mut m.rejected));
            let methods = methods.chain([(&mut ssi.modes, &mut ssi.rejected)]);
            for (modes, rejected) in methods.chain([(&mut fdd.modes, &mut fdd.rejected)]) {
                excitation::set_aside_excitation(modes, rejected, peaks, frf);
            }
        }
        let verdicts = verdicts::verdicts(
            &input_output
                .iter()
                .map(|m| (m.method, m.modes.as_slice()))
                .chain([
                    (ssi.method, ssi.modes.as_slice()),
                    (fdd.method, fdd.modes.as_slice()),
                ])
                .collect::<Vec<_>>(),
        );
        Ok(RecordModes {
            records: estimation.sampling.records.clone(),
            dt: estimation.sampling.dt,
            samples: runs.iter().map(RunView::len).collect(),
            excitation: first
                .excitation
                .map_or_else(|| "none (ambient)".to_owned(), |e| e.channel.name()),
            channels: channels.iter().map(|c| c.name()).collect(),
            floors: floors.iter().map(|(floor, _)| *floor).collect(),
            frf,
            spectrum,
            ssi,
            input_output,
            fdd,
            verdicts,
            options: estimation.options.clone(),
        })
    }
}

/// What the spectra and both methods are estimated with: the options, the runs' sampling, the
/// Welch estimator and the runs as it takes them.
struct Estimation<'s> {
    options: &'s IdentifyOptions,
    sampling: Sampling,
    roving: bool,
    welch: Welch,
    spectral_runs: Vec<Run<'s>>,
    per_channel: Vec<Vec<Run<'s>>>,
    /// Per run, per response, its channel's index among every run's channels.
    run_channels: Vec<Vec<usize>>,
}

impl Estimation<'_> {
    /// The responses' total spectrum (on a roving test, each channel's from the runs that
    /// measured it, summed).
    fn total_spectrum(&self) -> Result<SpectrumReport, IdentifyError> {
        let method_err = |method| self.sampling.method_err(method);
        let (frequencies, total) = if self.roving {
            let mut total = vec![0.0; self.sampling.segment_length / 2 + 1];
            for runs in &self.per_channel {
                let spectra = self
                    .welch
                    .output_spectra(runs)
                    .map_err(method_err("the spectra"))?;
                for (t, v) in total.iter_mut().zip(spectra.auto(0)) {
                    *t += v;
                }
            }
            (self.welch.frequencies(), total)
        } else {
            let spectra = self
                .welch
                .output_spectra(&self.spectral_runs)
                .map_err(method_err("the spectra"))?;
            (spectra.frequencies.clone(), spectra.total())
        };
        Ok(SpectrumReport { total, frequencies })
    }

    /// The force's spectrum (every run's), when it was measured and varies: where it excites
    /// the structure.
    fn force_spectrum(&self, runs: &[RunView<'_>]) -> Result<Option<Vec<f64>>, IdentifyError> {
        let excited = runs.iter().filter_map(|r| r.excitation).any(|e| {
            let v = &e.values;
            let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
            v.iter().any(|x| (x - mean).abs() > 0.0)
        });
        if !excited {
            return Ok(None);
        }
        let forces: Vec<[&[f64]; 1]> = runs
            .iter()
            .filter_map(|r| r.excitation.map(|e| [e.values.as_slice()]))
            .collect();
        let force_runs: Vec<Run<'_>> = forces
            .iter()
            .map(|f| Run {
                input: None,
                outputs: f,
            })
            .collect();
        let force = self
            .welch
            .output_spectra(&force_runs)
            .map_err(self.sampling.method_err("the force's spectrum"))?;
        Ok(Some(force.auto(0)))
    }

    /// SSI-COV's modes. It needs every run to measure the same channels: on a roving test it
    /// reads the first run alone, and its shapes are that run's.
    fn output_only(
        &self,
        first: &RunView<'_>,
        floors: &[(usize, (usize, i32))],
        screen: &ScreenOptions,
        evidence: Peaks,
    ) -> Result<MethodModes, IdentifyError> {
        let ssi_runs = if self.roving {
            &self.spectral_runs[..1]
        } else {
            &self.spectral_runs[..]
        };
        let ssi_floors = if self.roving {
            shape_floors(
                &first
                    .responses
                    .iter()
                    .map(|s| s.channel)
                    .collect::<Vec<_>>(),
            )
        } else {
            floors.to_vec()
        };
        let ssi_orders = ssi_cov(ssi_runs, self.sampling.dt, &self.options.ssi())
            .map_err(self.sampling.method_err("SSI-COV"))?;
        self.chosen_modes("SSI-COV", None, ssi_orders, screen, &ssi_floors, evidence)
    }

    /// FDD/EFDD's modes over `band`, screened as the others' (on a roving test, the first
    /// run's, like SSI-COV). Set aside: a mode where no measured curve peaks (`evidence`: the
    /// FRF when the force was measured, the responses' spectrum otherwise), or where that
    /// FRF's coherence stays below [`FDD_PEAK_COHERENCE`] within two bins, or whose bell
    /// reads a frequency away from its peak ([`Rejection::NoPeak`]: the singular value's
    /// shoulder beside a mode, or its noise; the lab frame forced over 0–250 Hz had 8.48 and
    /// 14.01 Hz beside its 9.03 and 13.43 Hz); a peak inside a higher peak's bell
    /// ([`Rejection::Unresolved`]: the same resonance); a peak no one shape holds
    /// ([`Rejection::Unseparated`]: the noise's).
    fn non_parametric(
        &self,
        first: &RunView<'_>,
        floors: &[(usize, (usize, i32))],
        screen: &ScreenOptions,
        band: (f64, f64),
        evidence: Peaks,
    ) -> Result<FddModes, IdentifyError> {
        let (runs, floors) = if self.roving {
            let channels: Vec<Channel> = first.responses.iter().map(|s| s.channel).collect();
            (&self.spectral_runs[..1], shape_floors(&channels))
        } else {
            (&self.spectral_runs[..], floors.to_vec())
        };
        let mut spectra = self
            .welch
            .output_spectra(runs)
            .map_err(self.sampling.method_err("FDD's spectra"))?;
        let mut welch = &self.welch;
        let averaging = self.averaging(spectra.segments)?;
        if let Some(averaging) = averaging.as_ref() {
            spectra = averaging
                .output_spectra(runs)
                .map_err(self.sampling.method_err("FDD's spectra"))?;
            welch = averaging;
        }
        let found = fdd(&spectra, welch.window(), &FddOptions::over(band));
        let (modes, mut rejected) = screen_modes(found.modes, screen);
        let modes = screen_by_peaks(modes, &mut rejected, &evidence.of());
        let (modes, weak): (Vec<_>, Vec<_>) = modes
            .into_iter()
            .partition(|m| evidence.coherent_near(m.frequency, FDD_PEAK_COHERENCE));
        rejected.extend(
            weak.into_iter()
                .map(|m| RejectedMode::new(m, Rejection::NoPeak)),
        );
        let shoulders = found.shoulders.into_iter();
        rejected.extend(shoulders.map(|m| RejectedMode::new(m, Rejection::Unresolved)));
        let off_peak = found.off_peak.into_iter();
        rejected.extend(off_peak.map(|m| RejectedMode::new(m, Rejection::NoPeak)));
        let unseparated = found.unseparated.into_iter();
        rejected.extend(unseparated.map(|m| RejectedMode::new(m, Rejection::Unseparated)));
        rejected.sort_by(|a, b| a.mode.frequency.total_cmp(&b.mode.frequency));
        Ok(FddModes {
            method: "FDD/EFDD",
            band,
            first_singular: found.first_singular,
            modes: record_modes(modes, &floors),
            rejected,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    /// A force with power in 11 of 500 bins (a narrow band, as a mass damper drives a tower)
    /// and a broadband one: the excited band is the narrow band's bins, and the broadband
    /// force's first to last bin. With the 90th percentile alone as the typical level the
    /// narrow band's empty bins set it, and every bin counted as excited.
    #[test]
    fn a_narrow_band_force_excites_its_band_only() {
        let frequencies: Vec<f64> = (0..500).map(|k| 0.1 * k as f64).collect();
        let narrow: Vec<f64> = (0..500)
            .map(|k| if (20..=30).contains(&k) { 1.0 } else { 1e-12 })
            .collect();
        let ((low, high), (low_edge, high_edge)) =
            excited_band(&frequencies, &narrow).expect("the force has power");
        assert_eq!((low, high), (frequencies[20], frequencies[30]));
        assert!(low_edge && high_edge);
        let broad: Vec<f64> = (0..500)
            .map(|k| 1.0 + 0.3 * ((k as f64) * 0.7).sin())
            .collect();
        let ((low, high), _) = excited_band(&frequencies, &broad).expect("the force has power");
        assert_eq!((low, high), (frequencies[1], frequencies[499]));
    }
    use numerics::modal::{mac, modes};
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    use std::path::Path;
    use structure::{Excitation, Structure};

    /// A four-storey building shaken at its top floor, measured by acc1, vel2, disp3 and acc4
    /// (mixed quantities, so the displacement shapes need each channel's power of λ), exact
    /// zero-order-hold simulation, 2 % sensor noise; 900 s at 100 Hz.
    fn record(structure: &Structure, seed: u64) -> Measurement {
        let n = structure.storeys();
        let ss = structure.state_space().expect("state space");
        let dt = 0.01;
        let mut augmented = DMatrix::zeros(2 * n + 1, 2 * n + 1);
        augmented.view_mut((0, 0), (2 * n, 2 * n)).copy_from(&ss.a);
        augmented.view_mut((0, 2 * n), (2 * n, 1)).copy_from(&ss.b);
        let exponential = (augmented * dt).exp();
        let ad = exponential.view((0, 0), (2 * n, 2 * n)).into_owned();
        let bd = exponential.view((0, 2 * n), (2 * n, 1)).into_owned();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let unit = Normal::new(0.0, 1.0).expect("unit normal");
        let samples = 90_000;
        let force: Vec<f64> = (0..samples).map(|_| 50.0 * unit.sample(&mut rng)).collect();
        let names = ["acc1", "vel2", "disp3", "acc4"];
        let mut columns = vec![Vec::with_capacity(samples); names.len()];
        let mut x = DVector::zeros(2 * n);
        for u in &force {
            let acc = &ss.c * &x + &ss.d * *u;
            columns[0].push(acc[0]);
            columns[1].push(x[n + 1]);
            columns[2].push(x[2]);
            columns[3].push(acc[3]);
            x = &ad * &x + &bd * *u;
        }
        for column in &mut columns {
            let rms = (column.iter().map(|v| v * v).sum::<f64>() / samples as f64).sqrt();
            for v in column.iter_mut() {
                *v += 0.02 * rms * unit.sample(&mut rng);
            }
        }
        let mut named = vec![
            (
                "time".to_owned(),
                (0..samples).map(|k| k as f64 * dt).collect(),
            ),
            ("force".to_owned(), force),
        ];
        named.extend(names.iter().map(|s| s.to_string()).zip(columns));
        Measurement::from_named_columns(Path::new("synthetic"), named, &Default::default())
            .expect("a valid record")
    }

    #[test]
    fn both_methods_find_the_modes_of_a_mixed_channel_record() {
        let mut structure =
            Structure::uniform(4, 1000.0, 0.0, 2.0e6, Excitation::Force { floor: 4 });
        // Storey dampers proportional to the stiffness: 1 % on the first mode.
        let first = structure.natural_frequencies()[0] * 2.0 * std::f64::consts::PI;
        structure.damping = structure
            .stiffness
            .iter()
            .map(|k| 2.0 * 0.01 * k / first)
            .collect();
        let exact = modes(
            &structure.mass_matrix(),
            &structure.damping_matrix(),
            &structure.stiffness_matrix(),
        )
        .expect("exact modes");
        let found =
            identify(&[record(&structure, 5)], &IdentifyOptions::default()).expect("identified");
        assert_eq!(found.floors, vec![1, 2, 3, 4]);
        assert!(found.frf.is_some());
        let io = found.input_output.as_ref().expect("LSCF ran");
        for method in [io, &found.ssi] {
            assert_eq!(method.modes.len(), exact.len(), "{}", method.method);
            for (m, e) in method.modes.iter().zip(&exact) {
                let f = m.identified.frequency / e.frequency - 1.0;
                let z = m.identified.damping / e.damping - 1.0;
                let shape = mac(&m.displacement_shape, &e.shape);
                println!(
                    "{}: {:.4} Hz ({:+.3} %), ζ {:.4} % ({:+.2} %), MAC {:.5}",
                    method.method,
                    m.identified.frequency,
                    100.0 * f,
                    100.0 * m.identified.damping,
                    100.0 * z,
                    shape
                );
                // The bars. Measured: LSCF within 0.012 % in frequency, 0.21 % in
                // damping, MAC ≥ 0.99987; SSI-COV within 0.28 %, 6.9 %, MAC ≥ 0.9984.
                assert!(f.abs() < 0.005, "{} {f}", method.method);
                assert!(z.abs() < 0.10, "{} {z}", method.method);
                assert!(shape > 0.99, "{} MAC {shape}", method.method);
            }
        }
        assert_eq!(found.observed().len(), exact.len());
    }

    #[test]
    fn bad_options_are_refused_before_any_work() {
        let options = IdentifyOptions {
            max_order: 7,
            ..IdentifyOptions::default()
        };
        assert!(options
            .validate()
            .expect_err("odd")
            .to_string()
            .contains("--max-order"));
        let options = IdentifyOptions {
            band: Some((5.0, 2.0)),
            ..IdentifyOptions::default()
        };
        assert!(options
            .validate()
            .expect_err("reversed")
            .to_string()
            .contains("--band"));
        assert_eq!(default_segment(120_000), 32_768);
    }
}
