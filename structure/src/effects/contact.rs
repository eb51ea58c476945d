//! Gap contact (a bumper) across a storey: no force while the drift is inside the gap, a linear
//! spring once the gap has closed. Bilinear, so the force is continuous at the gap.

use serde::{Deserialize, Serialize};

use super::{add_storey_force, drift, Effect, RealParam};

/// Which direction of drift closes the gap.
pub const SIDE_BOTH: i32 = 0;
/// The upper floor moving ahead of the lower one (positive drift) closes it.
pub const SIDE_POSITIVE: i32 = 1;
/// The upper floor moving back relative to the lower one (negative drift) closes it.
pub const SIDE_NEGATIVE: i32 = -1;

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Contact {
    /// Clearance before contact, m.
    pub gap: f64,
    /// Contact stiffness once closed, N/m.
    pub stiffness: f64,
    pub side: i32,
}

impl Contact {
    /// Contact force for a drift `d` (positive resists positive drift).
    #[inline]
    pub fn force_at(&self, d: f64) -> f64 {
        let closes_positive = self.side != SIDE_NEGATIVE;
        let closes_negative = self.side != SIDE_POSITIVE;
        if closes_positive && d > self.gap {
            self.stiffness * (d - self.gap)
        } else if closes_negative && d < -self.gap {
            self.stiffness * (d + self.gap)
        } else {
            0.0
        }
    }
}

impl Contact {
    /// Switch functions at drift `d`: `d − gap` when positive drift closes the gap, `d + gap`
    /// when negative drift does; the force has a kink where one changes sign.
    #[inline]
    pub fn switches(&self, d: f64) -> [Option<f64>; 2] {
        [
            (self.side != SIDE_NEGATIVE).then_some(d - self.gap),
            (self.side != SIDE_POSITIVE).then_some(d + self.gap),
        ]
    }
}

const PARAMS: &[RealParam] = &[
    RealParam {
        suffix: "gap",
        unit: "m",
        start: 5e-4,
        min: 0.0,
        strictly: false,
        description: "clearance before contact",
    },
    RealParam {
        suffix: "stiffness",
        unit: "N/m",
        start: 9000.0,
        min: 0.0,
        strictly: false,
        description: "contact stiffness once the gap is closed",
    },
];

impl Effect for Contact {
    const KIND: &'static str = "contact";

    /// `contact{L}{U}` while both floors are single digits (`contact01`, `contact23`: the
    /// paper's names), `contact{L}to{U}` from floor 10 up (`contact9to10`, `contact10to11`), so
    /// that no name reads as two pairs of floors (`contact1011` could be 10–11 or 1–011) and no
    /// site's `prefix_` starts another's (`contact12_13_gap` would start with `contact12_`).
    fn prefix(location: usize) -> String {
        if location + 1 < 10 {
            format!("contact{}{}", location, location + 1)
        } else {
            format!("contact{}to{}", location, location + 1)
        }
    }
    fn where_(location: usize) -> String {
        if location == 0 {
            "between the ground and floor 1".into()
        } else {
            format!("between floors {} and {}", location, location + 1)
        }
    }
    fn real_params() -> &'static [RealParam] {
        PARAMS
    }
    fn integer_params() -> &'static [(&'static str, i32, i32, i32, &'static str)] {
        &[(
            "side",
            SIDE_BOTH,
            -1,
            1,
            "which drift closes the gap: 1 positive (upper floor ahead), -1 negative, 0 both",
        )]
    }
    fn at_start(_location: usize) -> Self {
        Contact {
            gap: PARAMS[0].start,
            stiffness: PARAMS[1].start,
            side: SIDE_BOTH,
        }
    }
    fn real(&self, index: usize) -> f64 {
        [self.gap, self.stiffness][index]
    }
    fn set_real(&mut self, index: usize, value: f64) {
        match index {
            0 => self.gap = value,
            _ => self.stiffness = value,
        }
    }
    fn integer(&self, _index: usize) -> i32 {
        self.side
    }
    fn set_integer(&mut self, _index: usize, value: i32) {
        self.side = value;
    }
    #[inline]
    fn add_force(&self, location: usize, y: &[f64], _v: &[f64], g: &mut [f64]) {
        add_storey_force(location, self.force_at(drift(y, location)), g);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn contact(side: i32) -> Contact {
        Contact {
            gap: 1e-3,
            stiffness: 9000.0,
            side,
        }
    }

    #[test]
    fn no_force_inside_the_gap() {
        for side in [SIDE_BOTH, SIDE_POSITIVE, SIDE_NEGATIVE] {
            for d in [-1e-3, -5e-4, 0.0, 5e-4, 1e-3] {
                assert_eq!(contact(side).force_at(d), 0.0, "side {side}, drift {d}");
            }
        }
    }

    #[test]
    fn force_is_continuous_at_the_gap_and_restoring_beyond_it() {
        let c = contact(SIDE_BOTH);
        let eps = 1e-12;
        assert!(c.force_at(1e-3 + eps).abs() < 1e-8);
        assert!(c.force_at(-1e-3 - eps).abs() < 1e-8);
        assert!(
            (c.force_at(2e-3) - 9.0).abs() < 1e-12,
            "k·(d − gap) = 9000·1e-3"
        );
        assert!((c.force_at(-2e-3) + 9.0).abs() < 1e-12);
    }

    #[test]
    fn one_sided_contact_ignores_the_other_direction() {
        assert!(contact(SIDE_POSITIVE).force_at(2e-3) > 0.0);
        assert_eq!(contact(SIDE_POSITIVE).force_at(-2e-3), 0.0);
        assert!(contact(SIDE_NEGATIVE).force_at(-2e-3) < 0.0);
        assert_eq!(contact(SIDE_NEGATIVE).force_at(2e-3), 0.0);
    }

    #[test]
    fn storey_force_acts_on_both_floors_with_opposite_signs() {
        let c = contact(SIDE_BOTH);
        let mut g = [0.0; 3];
        // storey 2 (floors 2–3): floor 3 ahead of floor 2 by 3 mm.
        c.add_force(2, &[0.0, 1e-3, 4e-3], &[0.0; 3], &mut g);
        assert!(
            (g[2] - 18.0).abs() < 1e-9 && (g[1] + 18.0).abs() < 1e-9 && g[0] == 0.0,
            "{g:?}"
        );
    }
}
