//! An FRF fit's modes judged by how many model orders make them, against its best-supported
//! mode: automated OMA's cluster-size rule. A structural mode, once the fit's order reaches
//! it, stands at nearly every order after; a pole the fit makes of noise comes and goes.

use numerics::modal::stabilisation::{IdentifiedMode, RejectedMode, Rejection};

use super::peaks::explained;
use super::MethodModes;

/// The least share of the largest cluster's orders a mode's cluster holds. Measured on the
/// project's records (`tests/modal_*.rs`, `tests/modal_bundled.rs`, `tests/modal_evidence.rs`,
/// LSCF): structural modes hold 0.52–1.00 of the largest cluster (the lowest: the paper rig's
/// dataset2 5.75 Hz, 13 of 25, set aside anyway as one resonance with 5.96 Hz; then the
/// ten-storey tower's top mode, 19 of 35, and the eight-storey one's 6.54 Hz, 9 of 16);
/// the pole of noise that passed every other screen on the lab frame's third run with white
/// sensor noise only, 39.41 Hz, 7 of 17 (0.41). The bar sits between. (The second run's
/// 55.64 Hz, 7 of 14 orders, is not told apart by its size: the misfit screen sets it aside,
/// `shoulder::screened_by_misfit`.)
pub const MIN_SHARE_OF_LARGEST: f64 = 0.45;

/// Splits `modes` into those made of at least [`MIN_SHARE_OF_LARGEST`] of the
/// best-supported mode's orders and those set aside ([`Rejection::FewOrders`], appended to
/// `rejected`, which stays sorted by frequency). A mode that first forms above `asked` (the
/// highest order asked for: the sweep went on for a peak no mode explained) is judged
/// against the orders from where it formed: it could not stand at the orders below (the lab
/// frame forced over 0–250 Hz: its 3.17 Hz formed above order 40, with 9 orders where the
/// others held 20 and more).
pub(super) fn screen_by_orders(
    modes: Vec<IdentifiedMode>,
    rejected: &mut Vec<RejectedMode>,
    asked: usize,
) -> Vec<IdentifiedMode> {
    let largest_from = |from: usize| {
        modes
            .iter()
            .map(|m| m.orders.iter().filter(|o| **o >= from).count())
            .max()
            .unwrap_or(0)
    };
    let needed: Vec<f64> = modes
        .iter()
        .map(|m| {
            let first = m.orders.iter().copied().min().unwrap_or(0);
            let from = if first > asked { first } else { 0 };
            MIN_SHARE_OF_LARGEST * largest_from(from) as f64
        })
        .collect();
    let (kept, few): (Vec<_>, Vec<_>) = modes
        .into_iter()
        .zip(needed)
        .partition(|(m, needed)| m.orders.len() as f64 >= *needed);
    let kept: Vec<IdentifiedMode> = kept.into_iter().map(|(m, _)| m).collect();
    let few = few.into_iter().map(|(m, _)| m);
    rejected.extend(few.map(|mode| RejectedMode::new(mode, Rejection::FewOrders)));
    rejected.sort_by(|a, b| a.mode.frequency.total_cmp(&b.mode.frequency));
    kept
}

/// The modes of an FRF fit of too few channels for a shape to tell noise from a mode: those
/// chosen from the orders asked for (`base`, up to `asked`), and of those chosen from the
/// whole sweep (`full`) the ones at an FRF peak the sweep went on for (`sought`, within two
/// bins of `bins`) that no mode of `base` explains; the whole sweep's other modes formed past
/// `asked` set aside ([`Rejection::Unsought`]). The diagram is the whole sweep's. Measured on
/// the lab frame's single-channel runs (`tests/modal_lab.rs`): forced over 0–250 Hz, the sweep
/// went on for the 0.39 %-damped 3.17 Hz peak, which a mode formed past order 40 explains;
/// forced over 1–60 Hz with 5 % coloured noise, run 3's whole sweep (to order 100) split
/// 3.17 and 9.03 Hz into doubles and made modes of noise at 8.89–44.1 Hz that passed every
/// other screen, where the orders asked for give the three modes alone.
pub(super) fn with_sought(
    mut base: MethodModes,
    full: MethodModes,
    sought: &[f64],
    asked: usize,
    bins: &[f64],
) -> MethodModes {
    let at_sought = |m: &IdentifiedMode| {
        sought.iter().any(|p| {
            explained(*p, std::slice::from_ref(m), bins)
                && !base
                    .modes
                    .iter()
                    .any(|b| explained(*p, std::slice::from_ref(&b.identified), bins))
        })
    };
    let late = |m: &IdentifiedMode| m.orders.iter().copied().min().unwrap_or(0) > asked;
    let mut added = Vec::new();
    let mut unsought = Vec::new();
    for m in full.modes {
        if at_sought(&m.identified) {
            added.push(m);
        } else if late(&m.identified) {
            unsought.push(RejectedMode::new(m.identified, Rejection::Unsought));
        }
    }
    base.modes.extend(added);
    base.modes
        .sort_by(|a, b| a.identified.frequency.total_cmp(&b.identified.frequency));
    base.rejected.extend(unsought);
    base.rejected
        .sort_by(|a, b| a.mode.frequency.total_cmp(&b.mode.frequency));
    base.diagram = full.diagram;
    base
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mode(frequency: f64, orders: usize) -> IdentifiedMode {
        IdentifiedMode {
            frequency,
            frequency_sd: 0.0,
            damping: 0.01,
            damping_sd: 0.0,
            shape: vec![numerics::modal::Complex::new(1.0, 0.0)],
            shape_sd: vec![0.0],
            mpc: 1.0,
            mpd: 0.0,
            orders: (0..orders).map(|o| 2 * o + 2).collect(),
        }
    }

    /// The lab frame's run 3 (white sensor noise): modes of 14, 16 and 17 orders stand, the
    /// 39.41 Hz pole of 7 is set aside with its reason.
    #[test]
    fn a_mode_of_few_orders_beside_the_largest_is_set_aside() {
        let modes = vec![
            mode(3.17, 14),
            mode(9.03, 16),
            mode(13.43, 17),
            mode(39.41, 7),
        ];
        let mut rejected = Vec::new();
        let kept = screen_by_orders(modes, &mut rejected, 40);
        let frequencies: Vec<f64> = kept.iter().map(|m| m.frequency).collect();
        assert_eq!(frequencies, vec![3.17, 9.03, 13.43]);
        assert_eq!(rejected.len(), 1);
        assert_eq!(rejected[0].mode.frequency, 39.41);
        assert_eq!(rejected[0].rejection, Rejection::FewOrders);
    }

    /// A mode that formed only once the sweep went past the 40 orders asked for (the lab frame
    /// forced over 0–250 Hz: 3.17 Hz from order 42, 9 orders beside modes of 25) is judged
    /// against the orders from there; the same 9 orders formed below 40 are few.
    #[test]
    fn a_mode_formed_past_the_orders_asked_for_is_judged_from_there() {
        let late = |frequency: f64, from: usize, orders: usize| IdentifiedMode {
            orders: (0..orders).map(|o| from + 2 * o).collect(),
            ..mode(frequency, 0)
        };
        let modes = vec![late(3.17, 42, 9), late(9.03, 10, 25), late(13.43, 12, 24)];
        let mut rejected = Vec::new();
        assert_eq!(screen_by_orders(modes, &mut rejected, 40).len(), 3);
        assert!(rejected.is_empty());
        let modes = vec![late(3.17, 22, 9), late(9.03, 10, 25), late(13.43, 12, 24)];
        let kept = screen_by_orders(modes, &mut rejected, 40);
        assert_eq!(kept.len(), 2);
        assert_eq!(rejected[0].mode.frequency, 3.17);
    }
}
