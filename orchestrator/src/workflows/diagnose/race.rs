//! Stage 3b, on a long record: the candidates raced on the record's head before any is fitted
//! on all of it.
//!
//! Round 1 fits every candidate alone on the whole record, and on a long record each of those
//! fits costs in proportion to its samples: on 16,384 samples of a 3-storey frame the fifteen
//! candidates of the library took 1.1–4.5 s each, nine tenths of the diagnosis. Most of them
//! explain nothing, and a fit on the record's first [`RACE_HEAD`] samples says so as well as
//! one on all of them: the candidates are first fitted alone on that head (the same fit, split
//! and starts, in parallel), ranked by their worst-floor held-out NMSE there, and only those a
//! later round could use go on to the whole record — the ones that cut the head's error by 10 %
//! or more (what the forward selection's later rounds try), at most [`SCREENED`],
//! always the best one. The others are reported in `raced_out` with their head's error.
//!
//! The race runs only where it can judge and pays: the default library (candidates the user
//! named are all fitted), a record of at least [`RACE_MIN`] samples, and an error that shows on
//! the head: the fits climb the record's ladder ([`super::fit::climbs`]), and every channel's
//! held-out NMSE on the head is at least [`RACE_SHOWS`] of the whole record's ([`shows`]). An
//! effect that only acts late in a record is fitted on every sample as before.

use super::baseline::Ground;
use super::channels::{worst, Channels};
use super::fit::{Fitted, Split};
use super::round_one::fit_alone;
use super::{Candidate, DiagnoseOptions, Diagnosis, Result};
use crate::twin::data::Measurement;

/// Candidates a round after the first tries, at most.
pub const SCREENED: usize = 6;

/// A later round tries only candidates that, fitted alone, brought the model's worst-floor
/// held-out NMSE to this share of it or below (a 10 % cut); the race on a record's head keeps
/// the same.
pub const CUT_ALONE: f64 = 0.9;

/// Samples of the record's head the candidates are raced on: the calibration ladder's first
/// rung, the head every fit on the whole record screens its starts on anyway (a race on twice
/// as many samples, whose starts then ran on all of them, cost more than the fits it spared on
/// 16,384 samples).
pub const RACE_HEAD: usize = crate::workflows::calibrate::ladder::STRETCH;

/// Records shorter than this are not raced: the head would be an eighth of the record or more,
/// and fitting every candidate on it would cost a good part of what it saves.
pub const RACE_MIN: usize = 8 * RACE_HEAD;

/// The share of each channel's whole-record held-out NMSE its head must show for a race. A
/// quarter: on the 131,072-sample bench record of a 3-storey frame with a hidden cubic spring
/// the linear twin's error grows along the record as the force's level wanders (floor 2: 35 %
/// NMSE on the head, 76 % on the whole, a share of 0.46), while the head shows the effect
/// plainly; an effect that only starts later leaves the head at the noise.
pub const RACE_SHOWS: f64 = 0.25;

/// A record's head the candidates are raced on: its samples and its held-out ones.
pub(super) struct Head {
    pub(super) data: Measurement,
    held_out: Vec<usize>,
}

impl Head {
    /// The head of `data` when a race can run on it under `split`: a record of at least
    /// [`RACE_MIN`] samples whose fits climb its ladder and whose transient ends early in the
    /// head.
    pub(super) fn of(data: &Measurement, split: &Split) -> Option<Head> {
        let runs = split.climb && data.len() >= RACE_MIN && split.first < RACE_HEAD / 2;
        runs.then(|| Head {
            data: data.head(RACE_HEAD),
            held_out: split
                .held_out
                .iter()
                .copied()
                .filter(|&k| k < RACE_HEAD)
                .collect(),
        })
    }

    /// The whole record's `split` cut to the head; its starts run on every sample of it.
    pub(super) fn split<'a>(&'a self, whole: &Split<'a>) -> Split<'a> {
        Split {
            mask: &whole.mask[..RACE_HEAD],
            held_out: &self.held_out,
            first: whole.first,
            climb: false,
        }
    }

    /// The worst-floor held-out NMSE of `predicted` on the head when its error shows there
    /// ([`shows`]) against the whole record's `held_out` samples; None when it does not.
    pub(super) fn error_shown(
        &self,
        channels: &Channels,
        predicted: &[Vec<f64>],
        held_out: &[usize],
    ) -> Option<f64> {
        let head = channels.nmse_on(predicted, &self.held_out);
        let whole = channels.nmse_on(predicted, held_out);
        shows(&head, &whole).then(|| worst(&head))
    }
}

/// A head shows the record's error when every channel's held-out NMSE on the head is at least
/// [`RACE_SHOWS`] of its held-out NMSE on the whole record: an effect that acts only later in
/// the record (a contact that starts to touch, a change) would not be judged on the head.
pub(super) fn shows(head: &[f64], whole: &[f64]) -> bool {
    head.iter().zip(whole).all(|(h, w)| *h >= RACE_SHOWS * w)
}

/// The candidates round 1 fits on the whole record: after a race on the record's head (see the
/// module) when the record is long, the library the default and the error shows on the head;
/// else `candidates` as they are. The race's outcome goes into the diagnosis.
pub(super) fn raced(
    g: &Ground,
    diagnosis: &mut Diagnosis,
    candidates: Vec<Candidate>,
) -> Result<Vec<Candidate>> {
    if g.options.candidates.is_some() || candidates.len() <= SCREENED {
        return Ok(candidates);
    }
    let Some(head) = Head::of(g.data, &g.split) else {
        return Ok(candidates);
    };
    let predicted = g.channels.predicted(g.base_run);
    let Some(before) = head.error_shown(g.channels, &predicted, g.split.held_out) else {
        return Ok(candidates);
    };
    let ground = Ground {
        data: &head.data,
        split: head.split(&g.split),
        ..*g
    };
    // The evidence is not read: the race ranks by held-out error alone.
    let (kept, out) = race(candidates, before, g.options, |c| {
        fit_alone(&ground, c, 0.0)
    });
    diagnosis.race_head = Some(RACE_HEAD);
    diagnosis.raced_out = out.iter().map(|(c, w)| (c.label(), *w)).collect();
    Ok(kept)
}

/// Every candidate fitted by `fit` on a record's head (in parallel), and the ones kept against
/// the model's worst-floor held-out NMSE `before` there ([`keep`]), in the given order; the
/// raced out with their head's error, best first.
pub(super) fn race<F>(
    candidates: Vec<Candidate>,
    before: f64,
    options: &DiagnoseOptions,
    fit: F,
) -> (Vec<Candidate>, Vec<(Candidate, f64)>)
where
    F: Fn(&Candidate) -> Result<Fitted> + Sync,
{
    let total = candidates.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    options.tell(&format!(
        "racing {total} candidates on the first {RACE_HEAD} samples"
    ));
    let errors = crate::parallel::on_threads(&candidates, options.threads, |c| {
        let fitted = fit(c);
        let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        options.tell(&format!(
            "race on the first {RACE_HEAD} samples: {k}/{total} fits"
        ));
        // A candidate whose fit fails on the head goes on to the whole record, where its
        // failure is reported as any is.
        fitted.map_or(f64::NEG_INFINITY, |f| worst(&f.nmse_held_out))
    });
    keep(candidates, errors, before)
}

/// The candidates kept from a race with these head `errors` (worst-floor held-out NMSE, -∞ for
/// a fit that failed) against the twin's `before`: those that cut it by 10 % or more, best
/// first, at most [`SCREENED`] of them, and always the best one (every failed one too);
/// the kept in the library's order, the rest best first.
pub(super) fn keep(
    candidates: Vec<Candidate>,
    errors: Vec<f64>,
    before: f64,
) -> (Vec<Candidate>, Vec<(Candidate, f64)>) {
    let mut ranked: Vec<(usize, Candidate, f64)> = candidates
        .into_iter()
        .zip(errors)
        .enumerate()
        .map(|(i, (c, e))| (i, c, e))
        .collect();
    ranked.sort_by(|a, b| a.2.total_cmp(&b.2));
    let failed = ranked.iter().filter(|r| r.2 == f64::NEG_INFINITY).count();
    let cutting = ranked[failed..]
        .iter()
        .take_while(|r| r.2 <= CUT_ALONE * before)
        .count()
        .clamp(1, SCREENED);
    let out: Vec<(Candidate, f64)> = ranked
        .split_off((failed + cutting).min(ranked.len()))
        .into_iter()
        .map(|(_, c, e)| (c, e))
        .collect();
    ranked.sort_by_key(|r| r.0);
    (ranked.into_iter().map(|(_, c, _)| c).collect(), out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use structure::effects::Kind;

    /// The race keeps the candidates that cut the head's error by 10 % or more, at most
    /// SCREENED, the best first; always the best one, even when none cuts; a failed fit goes
    /// on; nothing is lost, and the kept keep the library's order.
    #[test]
    fn the_race_keeps_what_a_later_round_could_use() {
        let library = Candidate::library(4);
        let n = library.len();
        // Storey 2's cubic explains the head; seven others cut it by 10 % or more.
        let errors: Vec<f64> = library
            .iter()
            .enumerate()
            .map(|(i, c)| match (c.kind, c.at) {
                (Kind::Cubic, 2) => 0.1,
                _ if i % 2 == 0 => 80.0 + i as f64,
                _ => 99.5,
            })
            .collect();
        let (kept, out) = keep(library.clone(), errors.clone(), 100.0);
        assert_eq!(kept.len(), SCREENED);
        assert_eq!(kept.len() + out.len(), n);
        let cubic = library
            .iter()
            .find(|c| c.kind == Kind::Cubic && c.at == 2)
            .unwrap();
        assert!(kept.contains(cubic));
        let index = |c: &Candidate| library.iter().position(|l| l == c).unwrap();
        assert!(kept.windows(2).all(|w| index(&w[0]) < index(&w[1])));
        assert!(out.windows(2).all(|w| w[0].1 <= w[1].1));
        let worst_kept = kept.iter().map(|c| errors[index(c)]).fold(0.0, f64::max);
        assert!(out.iter().all(|(_, e)| *e >= worst_kept));

        // None cuts by 10 %: the best alone goes on.
        let flat: Vec<f64> = (0..n).map(|i| 95.0 + i as f64 * 0.1).collect();
        let (kept, out) = keep(library.clone(), flat, 100.0);
        assert_eq!(kept, vec![library[0]]);
        assert_eq!(out.len(), n - 1);

        // A failed head fit goes on beside the best.
        let mut failing = vec![99.0; n];
        failing[3] = f64::NEG_INFINITY;
        failing[5] = 50.0;
        let (kept, out) = keep(library.clone(), failing, 100.0);
        assert_eq!(kept, vec![library[3], library[5]]);
        assert_eq!(out.len(), n - 2);
    }

    /// A head shows the record's error only when every channel's head error is at least
    /// RACE_SHOWS of its whole-record error: one channel quiet on the head (an effect acting
    /// later) stops the race.
    #[test]
    fn a_head_shows_the_error_only_when_every_channel_does() {
        assert!(shows(&[50.0, 40.0], &[60.0, 70.0]));
        assert!(shows(&[15.0, 17.5], &[60.0, 70.0]));
        assert!(!shows(&[50.0, 10.0], &[60.0, 70.0]));
    }
}
