//! Stage 3, candidates: the default library screened before any candidate is fitted through the
//! FMU — every candidate's linearised score from the twin's residual ([`super::discover::screen`])
//! — and only the candidates at the best sites kept.

use structure::effects::Placement;

use super::baseline::Ground;
use super::fit::Split;
use super::{discover, Candidate, Diagnosis, Result};
use crate::evaluation::stats::variance;

/// Candidates fitted through the FMU at most when the library is the default (the paper rig's
/// whole library is 15: contact at three storeys on three sides, cubic per storey, friction per
/// floor; a taller building's is 5 per storey).
pub const SCREEN_KEEP: usize = 15;

/// The default library is screened before any candidate is fitted through the FMU
/// ([`discover::screen`], the linearised score of every candidate from the twin's residual) and
/// only the candidates at this many sites are fitted: the sites (a storey, or a floor for
/// friction) whose best candidate scores best, every kind and side at each. A site rather than
/// a candidate, because a strong effect's linearisation can favour another kind at the same
/// storey (a strong cubic spring of storey 3 scores like a two-sided contact there) but not
/// another storey. Only when the screen is decisive: its best site's linearised force leaves at
/// most [`SCREEN_DECISIVE`] of the residual. Otherwise (the effect barely seen through the
/// linearisation: a cubic spring of a five-storey frame under ground motion seen by three
/// accelerometers left 0.98 of it, below friction at three floors) the best [`SCREEN_KEEP`]
/// candidates are fitted.
pub const SCREEN_SITES: usize = 3;

/// The screen decides by sites when its best site explains at least half the residual.
pub const SCREEN_DECISIVE: f64 = 0.5;

/// The screen's choice: when it is decisive, the candidates at the [`SCREEN_SITES`] sites
/// whose best candidate scores lowest (every kind and side there), else every candidate; at
/// most [`SCREEN_KEEP`] of them (the lowest scores first), in the library's order; and the rest
/// with their scores.
pub(super) fn screen_sites(
    candidates: Vec<Candidate>,
    scores: Vec<f64>,
) -> (Vec<Candidate>, Vec<(Candidate, f64)>) {
    let site = |c: &Candidate| (c.placement() == Placement::Floor, c.at);
    let mut best: Vec<((bool, usize), f64)> = Vec::new();
    for (c, &score) in candidates.iter().zip(&scores) {
        match best.iter_mut().find(|(s, _)| *s == site(c)) {
            Some((_, b)) => *b = b.min(score),
            None => best.push((site(c), score)),
        }
    }
    best.sort_by(|a, b| a.1.total_cmp(&b.1));
    let decisive = best.first().is_some_and(|b| b.1 <= SCREEN_DECISIVE);
    let take = if decisive { SCREEN_SITES } else { best.len() };
    let sites: Vec<(bool, usize)> = best.iter().take(take).map(|b| b.0).collect();
    let (mut kept, mut dropped): (Vec<_>, Vec<_>) = candidates
        .into_iter()
        .zip(scores)
        .enumerate()
        .partition(|(_, (c, _))| sites.contains(&site(c)));
    if kept.len() > SCREEN_KEEP {
        kept.sort_by(|a, b| a.1 .1.total_cmp(&b.1 .1));
        dropped.extend(kept.split_off(SCREEN_KEEP));
        kept.sort_by_key(|k| k.0);
    }
    dropped.sort_by(|a, b| a.1 .1.total_cmp(&b.1 .1));
    (
        kept.into_iter().map(|(_, (c, _))| c).collect(),
        dropped.into_iter().map(|(_, cs)| cs).collect(),
    )
}

/// Round 1's screen: the default library only at the sites whose force, linearised through
/// the structure, explains most of the residual (see `screen_sites`); given candidates as
/// they are. The screened-out go into the diagnosis with their scores.
pub(super) fn screened(
    g: &Ground,
    diagnosis: &mut Diagnosis,
    candidates: Vec<Candidate>,
) -> Result<Vec<Candidate>> {
    let Ground {
        data,
        options,
        storeys,
        split:
            Split {
                first,
                mask,
                held_out,
                ..
            },
        channels,
        reals,
        base_run,
        ..
    } = *g;
    let fitted_idx: Vec<usize> = (0..data.len()).filter(|&k| mask[k]).collect();
    Ok(if options.candidates.is_none() {
        options.tell(&format!("screening {} candidates", candidates.len()));
        let values = |p: char| -> Result<Vec<f64>> {
            (1..=storeys)
                .map(|i| reals.get(&format!("{p}{i}")))
                .collect()
        };
        let sensors = channels.sensors();
        let problem = discover::Problem {
            linear: discover::LinearPart {
                mass: values('m')?,
                damping: values('c')?,
                stiffness: values('k')?,
            },
            states: discover::States {
                drift: &base_run.drift,
                velocity: &base_run.velocity,
                acceleration: &base_run.acc,
            },
            sensors: &sensors,
            residual: channels.residuals(base_run),
            variance: channels
                .measured
                .iter()
                .map(|m| variance(&m[first..]))
                .collect(),
            dt: data.dt,
            fitted: &fitted_idx,
            held_out,
            first,
        };
        let scores = discover::screen(&problem, &candidates, options.threads);
        let (kept, dropped) = screen_sites(candidates, scores);
        diagnosis.screened_out = dropped.iter().map(|(c, s)| (c.label(), *s)).collect();
        kept
    } else {
        candidates
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use structure::effects::Kind;

    /// A decisive screen (its best site at most SCREEN_DECISIVE of the residual) keeps every
    /// candidate at its SCREEN_SITES best sites, and only those; an undecided one keeps the
    /// best SCREEN_KEEP; nothing is lost either way.
    #[test]
    fn a_decisive_screen_keeps_the_best_sites_candidates() {
        let library = Candidate::library(5);
        let site = |c: &Candidate| (c.placement() == Placement::Floor, c.at);
        // Storey 4's contact scores best, then storey 2's cubic, then friction on floor 1;
        // everything else explains little.
        let scores: Vec<f64> = library
            .iter()
            .map(|c| match (c.kind, c.at) {
                (Kind::Contact, 4) => 0.2,
                (Kind::Cubic, 2) => 0.6,
                (Kind::Friction, 1) => 0.7,
                _ => 0.95,
            })
            .collect();
        let (kept, dropped) = screen_sites(library.clone(), scores.clone());
        assert_eq!(kept.len() + dropped.len(), library.len());
        let best_sites: Vec<(bool, usize)> = [Kind::Contact, Kind::Cubic, Kind::Friction]
            .iter()
            .zip([4, 2, 1])
            .filter_map(|(k, at)| library.iter().find(|c| c.kind == *k && c.at == at))
            .map(site)
            .collect();
        assert_eq!(best_sites.len(), 3);
        for c in &library {
            assert_eq!(
                kept.contains(c),
                best_sites.contains(&site(c)),
                "{} kept: {}",
                c.label(),
                kept.contains(c)
            );
        }
        // Undecided: the best screen score above the bar keeps the best SCREEN_KEEP.
        let undecided: Vec<f64> = scores.iter().map(|s| s + SCREEN_DECISIVE).collect();
        let (kept, dropped) = screen_sites(library.clone(), undecided);
        assert_eq!(kept.len(), SCREEN_KEEP.min(library.len()));
        assert_eq!(kept.len() + dropped.len(), library.len());
        assert!(
            dropped.windows(2).all(|w| w[0].1 <= w[1].1),
            "dropped by score"
        );
    }
}
