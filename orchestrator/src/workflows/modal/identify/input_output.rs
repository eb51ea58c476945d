//! The input–output path: the measured FRF (H1; a short record's averaged over shorter
//! segments for its evidence), LSCF's order sweep over the band, the modes chosen from its
//! diagram and screened.

use structure::channel::Channel;

use super::peaks::{explained, Peaks};
use super::runs::evidence_segment;
use super::{
    band::fit_band, frf_report, orders, record_modes, shoulder, Estimation, FrfReport,
    IdentifyError, MethodModes, RunView, DEFAULT_BAND_TOP, EVIDENCE_SEGMENTS, LSCF_ORDER_REACH,
    LSCF_ORDER_STEP,
};
use numerics::modal::lscf::{highest_order, lscf, LscfOptions};
use numerics::modal::spectral::{Frf, Welch};
use numerics::modal::stabilisation::{
    forming_poles, screen_by_peaks, screen_modes, select_modes, ModelOrder, ScreenOptions,
    SelectionOptions, StabilisationDiagram, ONE_CHANNEL_AMONG,
};

/// LSCF's model orders, swept past the orders asked for (`asked`) while modes were forming
/// or FRF peaks unexplained; on an FRF of fewer than [`ONE_CHANNEL_AMONG`] channels, the
/// peaks the sweep went on for (`sought`).
pub(super) struct Sweep {
    pub(super) orders: Vec<ModelOrder>,
    pub(super) sought: Option<Vec<f64>>,
    pub(super) asked: usize,
}

impl Estimation<'_> {
    /// A method's stabilisation diagram over its model orders and the physical modes chosen
    /// from it, screened.
    pub(super) fn chosen_modes(
        &self,
        method: &'static str,
        band: Option<(f64, f64)>,
        orders: Vec<ModelOrder>,
        screen: &ScreenOptions,
        floors: &[(usize, (usize, i32))],
        evidence: Peaks,
    ) -> Result<MethodModes, IdentifyError> {
        let diagram = StabilisationDiagram::new(orders, self.options.stability)
            .map_err(self.sampling.method_err("the diagram"))?;
        let selection = self.selection(band.is_some());
        let modes = select_modes(&diagram, &selection).map_err(self.sampling.method_err(method))?;
        let (modes, mut rejected) = screen_modes(modes, screen);
        let modes = screen_by_peaks(modes, &mut rejected, &evidence.of());
        // An FRF fit's modes by their clusters' sizes (SSI-COV's true modes hold as few as a
        // third of its largest cluster's orders: the five-storey building's 5.02 Hz, 6 of 19).
        let modes = if band.is_some() {
            orders::screen_by_orders(modes, &mut rejected, self.options.max_order)
        } else {
            modes
        };
        Ok(MethodModes {
            method,
            band,
            modes: record_modes(modes, floors),
            rejected,
            diagram,
        })
    }

    /// How the modes are chosen from a diagram; an FRF fit's (`frf_fit`) damping of a mode
    /// narrower than a bin is leakage, not asked to be stable.
    pub(super) fn selection(&self, frf_fit: bool) -> SelectionOptions {
        SelectionOptions {
            damping_stability: self.options.selection.damping_stability && !frf_fit,
            ..self.options.selection
        }
    }

    /// LSCF's model orders over `band`: 2 to the largest order asked for (or the highest a
    /// narrow band's bins fit: a mass damper's 2.4–2.6 Hz alone is 41 bins, short of order 40's
    /// 42, and failed the whole identification), then on by
    /// [`LSCF_ORDER_STEP`] orders at a time, up to [`LSCF_ORDER_REACH`] times it, while
    /// [`Estimation::sweep_on`] finds modes still forming or FRF peaks no mode explains. The
    /// sweep also ends where the basis loses rank (a narrow band's short arc).
    pub(super) fn lscf_orders(
        &self,
        frf: &Frf,
        band: (f64, f64),
        evidence: &Peaks,
        screen: &ScreenOptions,
    ) -> Result<Sweep, IdentifyError> {
        let fits = highest_order(frf, band).max(2);
        let first = LscfOptions {
            max_order: self.options.max_order.min(fits),
            weighting: self.options.weighting,
            ..LscfOptions::over(band)
        };
        let mut orders = lscf(frf, &first).map_err(self.sampling.method_err("LSCF"))?;
        let reach = if self.options.extend_orders {
            LSCF_ORDER_REACH * self.options.max_order
        } else {
            self.options.max_order
        };
        let shapes_tell = frf.response.len() >= ONE_CHANNEL_AMONG;
        let peaks = evidence.peaks_within(band);
        let mut sought: Vec<f64> = Vec::new();
        loop {
            let top = orders.last().map_or(0, |o| o.order);
            // Short of the orders asked for: the basis lost rank (a narrow band).
            if top < first.max_order || top + first.order_step > reach {
                break;
            }
            let Some(unexplained) =
                self.sweep_on(&orders, evidence, &peaks, screen, shapes_tell)?
            else {
                break;
            };
            // On too few channels for a shape, the peaks sought are those unexplained at the
            // orders asked for, and the sweep goes on only while one of them still is: the
            // modes of noise the higher orders make would raise the highest mode and make the
            // noise peaks below it unexplained in turn (the lab frame's 1–60 Hz run 2 with
            // 5 % coloured noise: 48.3 and 51.1 Hz at order 60, then 40.6–46.0 Hz).
            if shapes_tell || top == first.max_order {
                sought.extend(unexplained);
            } else if !unexplained.iter().any(|p| sought.contains(p)) {
                break;
            }
            let next = LscfOptions {
                min_order: top + first.order_step,
                max_order: (top + LSCF_ORDER_STEP).min(reach),
                ..first
            };
            // An order past the basis' rank is an error of the next sweep alone: the orders
            // so far stand.
            match lscf(frf, &next) {
                Ok(more) if !more.is_empty() => orders.extend(more),
                _ => break,
            }
        }
        Ok(Sweep {
            orders,
            sought: (!shapes_tell).then_some(sought),
            asked: first.max_order,
        })
    }

    /// LSCF's modes over `band`: its sweep ([`Estimation::lscf_orders`]) and the modes chosen
    /// from it. On an FRF of too few channels for a shape to tell noise from a mode, the
    /// orders past those asked for add only the modes at the peaks they were swept on for
    /// ([`orders::with_sought`]): the higher orders of one channel split its modes and make
    /// modes of its noise (the lab frame's 1–60 Hz runs with 5 % coloured noise swept to
    /// order 100: run 3 lost 3.17 and 9.03 Hz to split doubles and gained 8.89–44.1 Hz).
    pub(super) fn lscf_modes(
        &self,
        frf: &Frf,
        band: (f64, f64),
        evidence: Peaks,
        screen: &ScreenOptions,
        floors: &[(usize, (usize, i32))],
    ) -> Result<MethodModes, IdentifyError> {
        let sweep = self.lscf_orders(frf, band, &evidence, screen)?;
        let swept_on = sweep.orders.last().is_some_and(|o| o.order > sweep.asked);
        let Some(sought) = sweep.sought.filter(|_| swept_on) else {
            return self.chosen_modes("LSCF", Some(band), sweep.orders, screen, floors, evidence);
        };
        let bins = evidence.frequencies.clone();
        let asked: Vec<ModelOrder> = sweep
            .orders
            .iter()
            .filter(|o| o.order <= sweep.asked)
            .cloned()
            .collect();
        let base =
            self.chosen_modes("LSCF", Some(band), asked, screen, floors, evidence.clone())?;
        let full = self.chosen_modes("LSCF", Some(band), sweep.orders, screen, floors, evidence)?;
        Ok(orders::with_sought(base, full, &sought, sweep.asked, &bins))
    }

    /// Whether LSCF's sweep goes on past `orders` (Some: the FRF `peaks` no mode explains
    /// yet, possibly none), and why:
    /// - the highest order holds stable poles no chosen mode is made of ([`forming_poles`])
    ///   where the FRF peaks (`evidence`: a pole of noise forming at the top order does not
    ///   take the sweep on, whose higher orders would make more of them), on an FRF of at
    ///   least [`ONE_CHANNEL_AMONG`] channels (`shapes_tell`): a stable shape across orders
    ///   is what tells a forming mode from noise, and one channel's shape says nothing (a lab
    ///   frame's single-channel runs, swept on for forming poles, gained ten modes of noise
    ///   between 40 and 56 Hz, where their FRFs have noise peaks of coherence 0.5);
    /// - nothing forming, but the FRF peaks where no mode is yet (a broad band whose modes
    ///   sit low in it: an eight-storey tower forced at its top over 0–50 Hz stood nowhere
    ///   at order 40, all eight modes by 120), or a peak below the highest mode standing
    ///   that no mode explains (a lab frame forced by white noise over 0–250 Hz had its
    ///   9.03 and 13.43 Hz at order 40, its 0.39 % 3.17 Hz not yet). The highest mode is
    ///   the highest the screens keep (`screen`'s and the FRF peak screen): above it the
    ///   FRF's noise has coherent wiggles, and a pole at the force's band edge (the lab
    ///   frame's 1–60 Hz single-channel runs: 57.2 Hz) would take the sweep on for them.
    fn sweep_on(
        &self,
        orders: &[ModelOrder],
        evidence: &Peaks,
        peaks: &[f64],
        screen: &ScreenOptions,
        shapes_tell: bool,
    ) -> Result<Option<Vec<f64>>, IdentifyError> {
        let diagram = StabilisationDiagram::new(orders.to_vec(), self.options.stability)
            .map_err(self.sampling.method_err("the diagram"))?;
        let selection = self.selection(true);
        let modes = select_modes(&diagram, &selection).map_err(self.sampling.method_err("LSCF"))?;
        let supported = evidence.of();
        let forming = shapes_tell
            && forming_poles(&diagram, &selection, &modes)
                .iter()
                .any(|p| supported.supports(p.frequency));
        let (standing, mut aside) = screen_modes(modes.clone(), screen);
        let standing = screen_by_peaks(standing, &mut aside, &supported);
        let top_mode = standing
            .iter()
            .map(|m| m.frequency)
            .fold(f64::NEG_INFINITY, f64::max);
        // Explained within two bins of the grid the peak was found on (a short record's
        // averaged FRF: dataset1's 8.20 Hz peak on 0.2 Hz bins is its 8.36 Hz mode).
        let unexplained: Vec<f64> = peaks
            .iter()
            .copied()
            .filter(|p| {
                (standing.is_empty() || *p < top_mode)
                    && !explained(*p, &modes, &evidence.frequencies)
            })
            .collect();
        Ok((forming || !unexplained.is_empty()).then_some(unexplained))
    }

    /// With a measured force and its FRF (`frf`, [`Estimation::measured_frf`]): the FRF's
    /// report, the input–output method's modes over the band asked for or the one the force
    /// excites (when that method is asked for), and on a single test (not roving) the FRF a
    /// mode's peak is judged on.
    pub(super) fn with_force(
        &self,
        frf: Frf,
        force_psd: &[f64],
        first: &RunView<'_>,
        channels: &[Channel],
        floors: &[(usize, (usize, i32))],
        screen: &ScreenOptions,
    ) -> Result<(FrfReport, Option<MethodModes>, Option<Peaks>), IdentifyError> {
        let band = match self.options.band {
            Some(band) => band,
            None => fit_band(&frf, force_psd, DEFAULT_BAND_TOP * self.sampling.nyquist),
        };
        if self.roving {
            let input_output = self
                .options
                .input_output
                .then(|| self.roving_modes(force_psd, floors, screen))
                .transpose()?;
            let report = frf_report(frf, channels, first, self.sampling.segment_length);
            return Ok((report, input_output, None));
        }
        let averaged = self.averaged_frf(&frf)?;
        let averaged = averaged.as_ref().unwrap_or(&frf);
        let evidence = Peaks::of_frf(averaged);
        let input_output = if self.options.input_output {
            let chosen = self.lscf_modes(&frf, band, evidence.clone(), screen, floors)?;
            let chosen = shoulder::restored_shoulders(chosen, averaged, floors);
            let chosen = shoulder::screened_by_misfit(chosen, averaged);
            let chosen = self.resolved_by_record(chosen, floors, screen);
            let evidence_bin = match averaged.frequencies.as_slice() {
                [a, b, ..] => b - a,
                _ => 0.0,
            };
            Some(self.refined_leaky(chosen, floors, evidence_bin, screen))
        } else {
            None
        };
        let report = frf_report(frf, channels, first, self.sampling.segment_length);
        Ok((report, input_output, Some(evidence)))
    }

    /// When the spectra average fewer than [`EVIDENCE_SEGMENTS`] segments (a short record
    /// taken whole, for its resolution), a Welch estimator of [`evidence_segment`]'s shorter
    /// segments: the FRF a mode's peak is judged on, and FDD's spectral matrix. A single
    /// segment's coherence is 1 at every bin, its FRF the noise's ragged ratio (every wiggle a
    /// coherent peak) and its spectral matrix of rank one (every peak a clean shape): the
    /// paper rig's 1,024-sample dataset1 had LSCF's 16.82 and 17.94 Hz (MPC 0.71, 0.73) pass
    /// the peak screen, where seven segments of 256 give coherence 0.18 and 0.34 on the one
    /// channel that peaks there, and FDD report seven peaks for three modes. None: the
    /// spectra are averaged enough (every record of 2,560 samples or more by default).
    pub(super) fn averaging(&self, segments: usize) -> Result<Option<Welch>, IdentifyError> {
        let segment = evidence_segment(self.sampling.shortest);
        if self.roving || segments >= EVIDENCE_SEGMENTS || segment >= self.sampling.segment_length {
            return Ok(None);
        }
        Welch::new(self.sampling.dt, segment)
            .map(Some)
            .map_err(self.sampling.method_err("the averaged spectra"))
    }

    /// The H1 FRF over [`Estimation::averaging`]'s segments, when the fitted one averages too
    /// few.
    pub(super) fn averaged_frf(&self, frf: &Frf) -> Result<Option<Frf>, IdentifyError> {
        let Some(welch) = self.averaging(frf.segments)? else {
            return Ok(None);
        };
        welch
            .h1(&self.spectral_runs)
            .map(Some)
            .map_err(self.sampling.method_err("the averaged FRF"))
    }

    /// The H1 FRF of every response channel (on a roving test, each channel's from the runs
    /// that measured it, joined).
    pub(super) fn measured_frf(&self) -> Result<Frf, IdentifyError> {
        if !self.roving {
            return self
                .welch
                .h1(&self.spectral_runs)
                .map_err(self.sampling.method_err("the FRF"));
        }
        let mut joined: Option<Frf> = None;
        for runs in &self.per_channel {
            let one = self
                .welch
                .h1(runs)
                .map_err(self.sampling.method_err("the FRF"))?;
            match joined.as_mut() {
                None => joined = Some(one),
                Some(j) => {
                    j.response.extend(one.response);
                    j.coherence.extend(one.coherence);
                    j.segments = j.segments.min(one.segments);
                }
            }
        }
        joined.ok_or(IdentifyError::Options("no response channel".into()))
    }
}
