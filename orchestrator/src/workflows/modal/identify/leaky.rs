//! A record's lightly damped modes, refined in the time domain. A mode whose half-power width
//! (2ζf) spans only a few bins of the Welch FRF leaks between segments: its decay outlasts a
//! segment, so LSCF reads a damping made by the window, not by the structure (the lab frame's
//! 0.39 %-damped 3.17 Hz mode came out at 0.9–1.1 % on 30 s runs, the five-storey building's
//! 0.35 %-damped first mode at +6 %). When the force was measured, the record is taken whole
//! through it ([`time_fit`], as the roving merge does per run): the leaky modes' poles refined
//! from LSCF's by the fit's residual (every mode in the fit, the others at LSCF's poles), with
//! sds from the residual's curvature. Modes wider than that keep LSCF's figures, which the
//! FRF resolves.

use numerics::modal::indicators::mac;
use numerics::modal::spectral::Run;
use numerics::modal::stabilisation::{IdentifiedMode, RejectedMode, Rejection, ScreenOptions};
use numerics::modal::time_fit;
use numerics::modal::Complex;

use super::roving::pole;
use super::{record_modes, Estimation, MethodModes};

/// A mode is refined in the time domain when its half-power width (LSCF's 2ζf, itself
/// widened by the leakage) spans fewer FRF bins than this.
pub const LEAKY_BINS: f64 = 4.0;

/// The least relative rise of the time-domain fit's residual, the mode left out, for a leaky
/// mode to stand ([`Rejection::NotInRecord`]). Measured (`tests/modal_*.rs`,
/// `tests/modal_bundled.rs`, `tests/modal_evidence.rs`, the bundled records): the structural
/// modes 0.126–1946 (the lowest a five-storey tower's top mode, 8.41 Hz, not leaky; the
/// lowest leaky one dataset3's 2.00 Hz, 0.316, its record's contact leaving a linear fit
/// 36 % of it); the poles LSCF made of dataset3's single-segment FRF at 17.27, 17.90 and
/// 18.85 Hz (the bumper's contact) 0.0026, 0.0020 and 0.0006 — no more than four free
/// columns fitted to the 1,024 samples' noise take by chance (4/1024). The bar sits between,
/// eight times the highest of them.
pub const MIN_RESIDUAL_RISE: f64 = 0.02;

impl Estimation<'_> {
    /// `method`'s leaky modes (narrower than [`LEAKY_BINS`] bins) with the frequency and
    /// damping of the record taken whole in the time domain through its measured force; the
    /// modes unchanged when the record has no force, is several runs, has no leaky mode, or
    /// the fit is singular, and a mode unchanged when its refined frequency moved by more than
    /// a bin (the time-domain fit did not hold to LSCF's peak). When the record sets modes aside
    /// (not needed, or one resonance with a kept mode), the kept leaky modes are refined again
    /// without them.
    pub(super) fn refined_leaky(
        &self,
        mut method: MethodModes,
        floors: &[(usize, (usize, i32))],
        evidence_bin: f64,
        screen: &ScreenOptions,
    ) -> MethodModes {
        let bin = 1.0 / (self.sampling.segment_length as f64 * self.sampling.dt);
        let Some(fit) = self.time_domain() else {
            return method;
        };
        let mut modes: Vec<IdentifiedMode> =
            method.modes.iter().map(|m| m.identified.clone()).collect();
        let leaky: Vec<usize> = (0..modes.len())
            .filter(|&i| 2.0 * modes[i].damping * modes[i].frequency < LEAKY_BINS * bin)
            .collect();
        if leaky.is_empty() {
            return method;
        }
        let start: Vec<(f64, f64)> = modes.iter().map(|m| (m.frequency, m.damping)).collect();
        let Some(refined) = fit.refine(&start, &leaky) else {
            return method;
        };
        let taken = fit.take_refined(&mut modes, &refined, &leaky, &start, bin);
        let screened = Screened {
            leaky: &leaky,
            peak_window: 2.0 * evidence_bin,
            screen,
        };
        let Some(rises) = fit.rises(&modes) else {
            fit.with_curvature_sds(&mut modes, &taken);
            method.modes = record_modes(modes, floors);
            return method;
        };
        let kept = screened.by_record(&modes, &rises, &mut method.rejected);
        let origin: Vec<(f64, f64)> = kept.iter().map(|&i| start[i]).collect();
        let mut taken: Vec<bool> = kept.iter().map(|&i| taken[i]).collect();
        let kept_leaky: Vec<usize> = (0..kept.len())
            .filter(|&k| leaky.contains(&kept[k]))
            .collect();
        let mut modes: Vec<IdentifiedMode> = kept.iter().map(|&i| modes[i].clone()).collect();
        // A pole set aside shared its resonance with one kept (two poles LSCF made of one
        // peak, each pulled off it by the other): the record taken whole again without it, the
        // kept leaky modes refined alone.
        if modes.len() < start.len() && !kept_leaky.is_empty() {
            let again: Vec<(f64, f64)> = modes.iter().map(|m| (m.frequency, m.damping)).collect();
            if let Some(refined) = fit.refine(&again, &kept_leaky) {
                let retaken = fit.take_refined(&mut modes, &refined, &kept_leaky, &origin, bin);
                taken.iter_mut().zip(retaken).for_each(|(t, r)| *t |= r);
            }
        }
        // The sds once, from the modes as they end.
        fit.with_curvature_sds(&mut modes, &taken);
        method.modes = record_modes(modes, floors);
        method
    }

    /// The record taken whole in the time domain through its measured force: None without a
    /// force or on several runs.
    pub(super) fn time_domain(&self) -> Option<TimeDomain<'_>> {
        let [run] = self.spectral_runs.as_slice() else {
            return None;
        };
        Some(TimeDomain {
            dt: self.sampling.dt,
            input: run.input?,
            run,
        })
    }
}

/// What judges the modes once the leaky ones are refined: which are leaky, the peak screen's
/// window (Hz: two bins of the FRF that judges peaks either side) and the split modes' MAC.
struct Screened<'a> {
    leaky: &'a [usize],
    peak_window: f64,
    screen: &'a ScreenOptions,
}

impl Screened<'_> {
    /// The places in `modes` of those kept: without (moved to `rejected`, sorted by frequency) the leaky ones the record
    /// taken whole does not need (`rises` below [`MIN_RESIDUAL_RISE`]: the misfit screen
    /// leaves a leaky mode alone, this judges it), and those of the same shape as a mode the
    /// record needs more within the peak screen's window of it: one FRF peak supports one
    /// mode of a shape ([`Rejection::Unresolved`]; the bumper's dataset3 had 6.03 and 9.00 Hz
    /// beside 5.96 and 8.73 Hz, MAC 0.99 and 0.98, 0.08 and 0.27 Hz apart on 0.2 Hz bins —
    /// the contact's stiffer state, which a linear fit reads as a second pole).
    fn by_record(
        &self,
        modes: &[IdentifiedMode],
        rises: &[f64],
        rejected: &mut Vec<RejectedMode>,
    ) -> Vec<usize> {
        let verdicts: Vec<Option<Rejection>> = (0..modes.len())
            .map(|i| self.verdict(modes, rises, i))
            .collect();
        let mut kept = Vec::with_capacity(modes.len());
        for (i, verdict) in verdicts.into_iter().enumerate() {
            match verdict {
                Some(rejection) => rejected.push(RejectedMode::new(modes[i].clone(), rejection)),
                None => kept.push(i),
            }
        }
        rejected.sort_by(|a, b| a.mode.frequency.total_cmp(&b.mode.frequency));
        kept
    }

    /// Why mode `i` of `modes` is set aside, if it is.
    fn verdict(&self, modes: &[IdentifiedMode], rises: &[f64], i: usize) -> Option<Rejection> {
        if self.leaky.contains(&i) && rises[i] < MIN_RESIDUAL_RISE {
            return Some(Rejection::NotInRecord);
        }
        let one_peak = |j: usize| {
            j != i
                && rises[j] > rises[i]
                && (modes[j].frequency - modes[i].frequency).abs() <= self.peak_window
                && mac(&modes[i].shape, &modes[j].shape) >= self.screen.split_mac
        };
        (0..modes.len())
            .any(one_peak)
            .then_some(Rejection::Unresolved)
    }
}

/// One run taken whole: its sampling step, measured force and responses.
pub(super) struct TimeDomain<'a> {
    dt: f64,
    input: &'a [f64],
    run: &'a Run<'a>,
}

impl TimeDomain<'_> {
    /// The modes at `leaky` given their `refined` frequency and damping, each unless it moved
    /// more than `bin` from LSCF's (`origin`: the fit did not hold to LSCF's peak); per mode,
    /// whether it took them.
    fn take_refined(
        &self,
        modes: &mut [IdentifiedMode],
        refined: &[(f64, f64)],
        leaky: &[usize],
        origin: &[(f64, f64)],
        bin: f64,
    ) -> Vec<bool> {
        let mut taken = vec![false; modes.len()];
        for &i in leaky {
            let (frequency, damping) = refined[i];
            if (frequency - origin[i].0).abs() <= bin {
                modes[i].frequency = frequency;
                modes[i].damping = damping;
                taken[i] = true;
            }
        }
        taken
    }

    /// The `taken` modes' frequency and damping sds from the residual's curvature at `modes`
    /// (their own where it is not curved upward).
    fn with_curvature_sds(&self, modes: &mut [IdentifiedMode], taken: &[bool]) {
        let at: Vec<(f64, f64)> = modes.iter().map(|m| (m.frequency, m.damping)).collect();
        for (i, _) in taken.iter().enumerate().filter(|(_, t)| **t) {
            if let Some((frequency_sd, damping_sd)) = self.curvature_sds(&at, i) {
                modes[i].frequency_sd = frequency_sd;
                modes[i].damping_sd = damping_sd;
            }
        }
    }

    /// The fit's residual (the outputs' relative residual powers, summed) at `modes`
    /// (frequency Hz, damping ratio).
    pub(super) fn residual(&self, modes: &[(f64, f64)]) -> Option<f64> {
        let poles: Vec<Complex> = modes.iter().map(|(f, z)| pole(*f, *z)).collect();
        time_fit::fit_residues(self.dt, self.input, self.run.outputs, &poles).map(|f| f.residual)
    }

    /// Per mode of `modes`, the relative rise of the fit's residual when it is left out.
    /// None when a fit is singular or leaves nothing.
    fn rises(&self, modes: &[IdentifiedMode]) -> Option<Vec<f64>> {
        let all: Vec<(f64, f64)> = modes.iter().map(|m| (m.frequency, m.damping)).collect();
        let whole = self.residual(&all).filter(|r| *r > 0.0)?;
        (0..all.len())
            .map(|i| {
                let mut less = all.clone();
                less.remove(i);
                self.residual(&less).map(|r| r / whole - 1.0)
            })
            .collect()
    }

    /// `modes` (frequency Hz, damping ratio) with those at `leaky` refined one after the
    /// other (twice over when several), the others held: a pattern search on the residual as
    /// [`time_fit::refine_poles`] makes (steps of 0.3 % in frequency and a factor 1.5 in
    /// damping, halved where no step improves, down to 0.001 %; damping within 0.01–30 %),
    /// over the leaky modes only — the modes the FRF resolves are right already, and a
    /// five-storey 300 s record refined whole took 4 s more. None when the fit is singular.
    fn refine(&self, modes: &[(f64, f64)], leaky: &[usize]) -> Option<Vec<(f64, f64)>> {
        let sweeps = if leaky.len() > 1 { 2 } else { 1 };
        time_fit::pattern_search(modes, leaky, sweeps, |m| {
            self.residual(m).unwrap_or(f64::INFINITY)
        })
    }

    /// Mode `i`'s frequency and damping sds from the residual's curvature at its minimum
    /// `modes`: a least-squares fit's parameter variance is 2σ²/S'' with σ² the residual per
    /// sample left (here per sample and output, against the outputs' powers), S'' the second
    /// difference over a tenth of the mode's half-power width (frequency) and a tenth of its
    /// damping. The residual is taken as white: sensor noise coloured at the mode makes the
    /// true sd larger. None when the residual is not curved upward there.
    fn curvature_sds(&self, modes: &[(f64, f64)], i: usize) -> Option<(f64, f64)> {
        let at_minimum = self.residual(modes)?;
        let (f, z) = modes[i];
        let samples = (self.input.len() * self.run.outputs.len()) as f64;
        let parameters = ((2 + 4 * modes.len()) * self.run.outputs.len()) as f64;
        let sigma2 = at_minimum / (samples - parameters).max(1.0);
        let sd = |step: f64, moved: &dyn Fn(f64) -> (f64, f64)| -> Option<f64> {
            let mut shifted = modes.to_vec();
            let mut at = |delta: f64| {
                shifted[i] = moved(delta);
                self.residual(&shifted)
            };
            let curvature = (at(step)? - 2.0 * at_minimum + at(-step)?) / (step * step);
            (curvature > 0.0).then(|| (2.0 * sigma2 / curvature).sqrt())
        };
        let frequency_sd = sd(0.1 * z * f, &|d| (f + d, z))?;
        let damping_sd = sd(0.1 * z, &|d| (f, z + d))?;
        Some((frequency_sd, damping_sd))
    }
}
