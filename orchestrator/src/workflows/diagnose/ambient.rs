//! The diagnosis of an ambient record: responses without the excitation, as a building's
//! permanent monitoring measures them (wind, traffic, microtremor). The twin cannot be run on
//! it, so the time domain has nothing to compare; the modes are the evidence. The record's
//! modes are identified output-only (SSI-COV) and set against the twin's with the band of
//! `twin compare` ([`ModalBand`]): none outside it is `none`; a mode outside it means the
//! structure's stiffness or mass changed, `recalibrate`, with the single change of one floor's
//! mass or one storey's stiffness that explains the identified frequencies best
//! ([`explain_shifts`]) and the runners-up, for the engineer to look at before recalibrating
//! on a record with the excitation measured.
//!
//! With the excitation measured the time domain is the sharper detector, and
//! [`super::diagnose`] decides on it: a storey 3 % softer in a five-storey building shaken at
//! the ground moved no mode beyond the band (at most −1.1 %) while its NMSE was 37–58 %,
//! against a tolerance of 0.5 %.

use std::time::Instant;

use serde::Serialize;

use super::Action;
use crate::record::AmbientRecord;
use crate::twin::Twin;
use crate::workflows::modal::{
    evidence_of, explain_shifts, identify_ambient, twin_modes, Explanation, IdentifyOptions,
    ModalBand, ModalError, ModalEvidence, ModalOptions, RecordModes, TwinModes,
};
use ::structure::Structure;

/// How many runners-up the reason names after the best explanations.
const RUNNERS_UP: usize = 2;
/// Explanations whose misfit is within this of the best (a sum of squared sds: one sd more in
/// one mode) fit as well.
pub const TIED_MISFIT: f64 = 1.0;

fn tied_for_best(explanations: &[Explanation]) -> usize {
    match explanations.first() {
        Some(best) => explanations
            .iter()
            .take_while(|e| e.misfit <= best.misfit + TIED_MISFIT)
            .count(),
        None => 0,
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct IdentifiedMode {
    pub frequency: f64,
    pub damping: f64,
    pub shape: Vec<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct AmbientDiagnosis {
    pub record: String,
    pub twin: String,
    /// `ambient`: the record has no excitation; only its modes were compared.
    pub evidence: &'static str,
    pub channels: Vec<String>,
    pub action: Action,
    pub reason: String,
    pub modes: ModalEvidence,
    /// The record's modes as identified (the `observed_mode` of `modes`' pairs counts from 1
    /// in this list): frequency (Hz), damping ratio, real displacement shape at `modes.floors`.
    pub identified: Vec<IdentifiedMode>,
    /// One floor's mass or one storey's stiffness changed, best explanation first (empty when
    /// no mode moved).
    pub explanations: Vec<Explanation>,
    /// How many of the first explanations fit equally well (within [`TIED_MISFIT`]): the
    /// frequencies cannot tell them apart (in a uniform building a storey's stiffness and the
    /// mirrored floor's mass, storey j and floor N + 1 − j, move every frequency alike).
    pub tied_for_best: usize,
    /// The misfit of the twin unchanged, to set the explanations' against.
    pub misfit_unchanged: f64,
    pub seconds: f64,
    /// The twin's own modes (its nominal structure's, no sampling), for the report's shapes.
    #[serde(skip)]
    pub twin_modes: TwinModes,
}

/// The verdict on an ambient record's modes: the single changes that explain them (best
/// first) and the misfit of none, the action and its reason.
struct Verdict {
    explanations: Vec<Explanation>,
    misfit_unchanged: f64,
    action: Action,
    reason: String,
}

/// No mode of the twin was identified in the record: nothing to go on.
fn nothing_identified(identified: &RecordModes, record: &AmbientRecord) -> Verdict {
    Verdict {
        explanations: Vec::new(),
        misfit_unchanged: 0.0,
        action: Action::None,
        reason: format!(
            "ambient record (no excitation column): the time domain cannot compare, and no \
             mode of the twin was identified in it ({} channels, {:.0} s); nothing to go on",
            identified.channels.len(),
            record.len() as f64 * record.dt
        ),
    }
}

/// Every identified mode is within the twin's band: none, with the largest shift named.
fn within_band(modes: &ModalEvidence) -> Verdict {
    let largest = modes
        .modes
        .iter()
        .max_by(|a, b| {
            a.pair
                .frequency_shift_percent
                .abs()
                .total_cmp(&b.pair.frequency_shift_percent.abs())
        })
        .map(|m| {
            format!(
                "largest shift mode {} {:+.2} %",
                m.pair.twin_mode, m.pair.frequency_shift_percent
            )
        })
        .unwrap_or_default();
    Verdict {
        explanations: Vec::new(),
        misfit_unchanged: 0.0,
        action: Action::None,
        reason: format!(
            "ambient record (no excitation column), compared by its modes: the {} modes \
             identified ({}) are within the twin's band ({largest})",
            modes.modes.len(),
            modes.method
        ),
    }
}

/// Some mode moved beyond the band: recalibrate, with the single changes of `structure` that
/// explain the shifts best and the runners-up.
fn shifted(structure: &Structure, modes: &ModalEvidence) -> Result<Verdict, ModalError> {
    let (explanations, unchanged) = explain_shifts(structure, modes)?;
    let describe = |e: &Explanation| format!("{} {:+.1} %", e.parameter, e.change_percent);
    let tied = tied_for_best(&explanations);
    let best: Vec<String> = explanations[..tied].iter().map(describe).collect();
    let next: Vec<String> = explanations[tied..]
        .iter()
        .take(RUNNERS_UP)
        .map(|e| format!("{} (misfit {:.1})", describe(e), e.misfit))
        .collect();
    let best = match explanations.first() {
        Some(first) if tied == 1 => format!(
            "; the single change that explains them best: {} (misfit {:.1} against \
             {unchanged:.1} unchanged; next: {})",
            best[0],
            first.misfit,
            next.join(", ")
        ),
        Some(first) => format!(
            "; the single changes that explain them best, which the frequencies \
             cannot tell apart: {} (misfit {:.1} against {unchanged:.1} unchanged; next: {})",
            best.join(" or "),
            first.misfit,
            next.join(", ")
        ),
        None => String::new(),
    };
    let reason = format!(
        "ambient record (no excitation column), compared by its modes: {} moved beyond \
         the twin's band, so the structure's stiffness or mass changed{best}; \
         recalibrate, on a record with the excitation measured",
        modes.describe_shifts()
    );
    Ok(Verdict {
        explanations,
        misfit_unchanged: unchanged,
        action: Action::Recalibrate,
        reason,
    })
}

/// Diagnose `twin` on an ambient record: its modes identified, set against the twin's, the
/// verdict.
pub fn diagnose_ambient(
    twin: &Twin,
    record: &AmbientRecord,
    band: ModalBand,
) -> Result<AmbientDiagnosis, ModalError> {
    let started = Instant::now();
    let identified = identify_ambient(std::slice::from_ref(record), &IdentifyOptions::default())
        .map_err(|e| ModalError::Options(format!("identifying {}: {e}", record.path.display())))?;
    let modes = evidence_of(twin, &identified, band)?;
    let structure = twin.structure()?;
    let Verdict {
        explanations,
        misfit_unchanged,
        action,
        reason,
    } = if modes.modes.is_empty() {
        nothing_identified(&identified, record)
    } else if modes.shifted.is_empty() {
        within_band(&modes)
    } else {
        shifted(&structure, &modes)?
    };
    Ok(AmbientDiagnosis {
        record: record.path.display().to_string(),
        twin: twin
            .source
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "(default twin)".into()),
        evidence: "ambient",
        channels: identified.channels.clone(),
        action,
        reason,
        identified: identified
            .observed()
            .iter()
            .map(|o| IdentifiedMode {
                frequency: o.frequency,
                damping: o.damping,
                shape: o.shape.iter().map(|c| c.re).collect(),
            })
            .collect(),
        modes,
        tied_for_best: tied_for_best(&explanations),
        explanations,
        misfit_unchanged,
        seconds: started.elapsed().as_secs_f64(),
        twin_modes: twin_modes(
            twin,
            &ModalOptions {
                samples: 0,
                ..Default::default()
            },
        )?,
    })
}
