//! One resonance the fit made two clusters of, decided by the record. The diagram's clusters
//! follow a mode's pole from order to order; where the pole's track splits in two (a pole of
//! noise beside the mode's, both within the cluster distance of the order below) the cluster
//! may follow the noise's branch, and the mode's own branch, at the higher orders, becomes a
//! cluster of its own, fewer in poles: the screen ([`Rejection::Unresolved`]) keeps the
//! larger. The paper rig's 20 s seed-7 record: the 8.379 Hz mode's cluster took 8.35 Hz
//! (orders 10–24) then a pole of noise drifting from 8.29 to 8.23 Hz with its damping falling
//! from 2.3 to 0.6 % (orders 26–40), median 8.2873 Hz (−1.09 %); the mode's own branch,
//! 8.39–8.41 Hz at 2.3 % over orders 24–40, was set aside. When the force was measured (one
//! run), the record taken whole through it in the time domain decides which of the two is the
//! resonance: the one whose pole leaves the smaller residual.

use numerics::modal::indicators::mac;
use numerics::modal::stabilisation::{
    half_power_overlap, IdentifiedMode, Rejection, ScreenOptions,
};

use super::{record_modes, Estimation, MethodModes};

impl Estimation<'_> {
    /// `method` with each kept mode exchanged for a mode set aside as one resonance with it
    /// (same shape within the screen's split distance or their half-power widths) when the
    /// record taken whole through its measured force fits better with the set-aside mode's
    /// pole in its place. Unchanged without a force, on several runs, or when a fit is
    /// singular.
    pub(super) fn resolved_by_record(
        &self,
        mut method: MethodModes,
        floors: &[(usize, (usize, i32))],
        screen: &ScreenOptions,
    ) -> MethodModes {
        let Some(fit) = self.time_domain() else {
            return method;
        };
        let mut modes: Vec<IdentifiedMode> =
            method.modes.iter().map(|m| m.identified.clone()).collect();
        let poles = |modes: &[IdentifiedMode]| -> Vec<(f64, f64)> {
            modes.iter().map(|m| (m.frequency, m.damping)).collect()
        };
        let Some(mut best) = fit.residual(&poles(&modes)) else {
            return method;
        };
        let mut exchanged = false;
        for set_aside in method
            .rejected
            .iter_mut()
            .filter(|r| r.rejection == Rejection::Unresolved)
        {
            let Some(i) = one_resonance(&modes, &set_aside.mode, screen) else {
                continue;
            };
            let mut trial = poles(&modes);
            trial[i] = (set_aside.mode.frequency, set_aside.mode.damping);
            if let Some(residual) = fit.residual(&trial).filter(|r| *r < best) {
                best = residual;
                std::mem::swap(&mut modes[i], &mut set_aside.mode);
                exchanged = true;
            }
        }
        if exchanged {
            modes.sort_by(|a, b| a.frequency.total_cmp(&b.frequency));
            method.modes = record_modes(modes, floors);
            method
                .rejected
                .sort_by(|a, b| a.mode.frequency.total_cmp(&b.mode.frequency));
        }
        method
    }
}

/// The place in `modes` of the mode nearest `other` in frequency that is one resonance with
/// it: the same shape (MAC at least the screen's split MAC) within the split distance or
/// their half-power widths.
fn one_resonance(
    modes: &[IdentifiedMode],
    other: &IdentifiedMode,
    screen: &ScreenOptions,
) -> Option<usize> {
    let apart = |m: &IdentifiedMode| (m.frequency - other.frequency).abs();
    (0..modes.len())
        .filter(|&i| {
            let m = &modes[i];
            (apart(m) <= screen.split_frequency * m.frequency
                || apart(m) < half_power_overlap(m, other))
                && mac(&m.shape, &other.shape) >= screen.split_mac
        })
        .min_by(|&a, &b| apart(&modes[a]).total_cmp(&apart(&modes[b])))
}
