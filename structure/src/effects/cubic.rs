//! Cubic (hardening, or softening when negative) stiffness of a storey: `f = k₃ δ³`.

use serde::{Deserialize, Serialize};

use super::{add_storey_force, drift, Effect, RealParam};

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Cubic {
    /// N/m³.
    pub stiffness: f64,
}

impl Cubic {
    /// Storey force at drift `d`.
    #[inline]
    pub fn force_at(&self, d: f64) -> f64 {
        self.stiffness * d * d * d
    }
}

const PARAMS: &[RealParam] = &[RealParam {
    suffix: "stiffness",
    unit: "N/m3",
    start: 1e9,
    min: f64::MIN,
    strictly: false,
    description: "cubic stiffness k3 in f = k3·drift³ (negative softens)",
}];

impl Effect for Cubic {
    const KIND: &'static str = "cubic";

    fn prefix(location: usize) -> String {
        format!("cubic{}", location + 1)
    }
    fn where_(location: usize) -> String {
        format!("of storey {}", location + 1)
    }
    fn real_params() -> &'static [RealParam] {
        PARAMS
    }
    fn at_start(_location: usize) -> Self {
        Cubic {
            stiffness: PARAMS[0].start,
        }
    }
    fn real(&self, _index: usize) -> f64 {
        self.stiffness
    }
    fn set_real(&mut self, _index: usize, value: f64) {
        self.stiffness = value;
    }
    #[inline]
    fn add_force(&self, location: usize, y: &[f64], _v: &[f64], g: &mut [f64]) {
        add_storey_force(location, self.force_at(drift(y, location)), g);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_at_zero_drift_odd_and_restoring() {
        let c = Cubic { stiffness: 1e9 };
        let force = |d: f64| {
            let mut g = [0.0; 3];
            c.add_force(0, &[d, 0.0, 0.0], &[0.0; 3], &mut g);
            g[0]
        };
        assert_eq!(force(0.0), 0.0);
        assert!((force(1e-3) - 1.0).abs() < 1e-12);
        assert_eq!(force(-1e-3), -force(1e-3));
    }
}
