//! Coulomb friction on a floor, smoothed: `f = F_c · tanh(ẏ / v_s)` so RK4 sees a smooth force.

use serde::{Deserialize, Serialize};

use super::{Effect, RealParam};

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Friction {
    /// Coulomb force level, N.
    pub force: f64,
    /// Velocity over which the force builds up, m/s.
    pub velocity_scale: f64,
}

const PARAMS: &[RealParam] = &[
    RealParam {
        suffix: "force",
        unit: "N",
        start: 0.1,
        min: 0.0,
        strictly: false,
        description: "Coulomb friction force",
    },
    RealParam {
        suffix: "velocity_scale",
        unit: "m/s",
        start: 1e-3,
        min: 0.0,
        strictly: true,
        description: "velocity scale of the tanh smoothing",
    },
];

impl Friction {
    #[inline]
    pub fn force_at(&self, velocity: f64) -> f64 {
        self.force * (velocity / self.velocity_scale).tanh()
    }
}

impl Effect for Friction {
    const KIND: &'static str = "friction";

    fn prefix(location: usize) -> String {
        format!("friction{}", location + 1)
    }
    fn where_(location: usize) -> String {
        format!("on floor {}", location + 1)
    }
    fn real_params() -> &'static [RealParam] {
        PARAMS
    }
    fn at_start(_location: usize) -> Self {
        Friction {
            force: PARAMS[0].start,
            velocity_scale: PARAMS[1].start,
        }
    }
    fn real(&self, index: usize) -> f64 {
        [self.force, self.velocity_scale][index]
    }
    fn set_real(&mut self, index: usize, value: f64) {
        match index {
            0 => self.force = value,
            _ => self.velocity_scale = value,
        }
    }
    #[inline]
    fn add_force(&self, location: usize, _y: &[f64], v: &[f64], g: &mut [f64]) {
        g[location] += self.force_at(v[location]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn opposes_motion_is_zero_at_rest_and_saturates() {
        let f = Friction {
            force: 0.5,
            velocity_scale: 1e-3,
        };
        assert_eq!(f.force_at(0.0), 0.0);
        assert!(
            f.force_at(0.1) > 0.0 && f.force_at(-0.1) < 0.0,
            "g is on the left-hand side: it resists motion"
        );
        assert!((f.force_at(0.1) - 0.5).abs() < 1e-12);
        // Continuous through zero: small velocity, small force.
        assert!(f.force_at(1e-9).abs() < 1e-6);
    }
}
