//! The substructures of the simulated real-time hybrid test, as pure models: the numerical one
//! (floors 1 and 2 with storeys 1 and 2) and the physical one (storey 3 with the one-sided
//! bumper between floors 2 and 3, and floor 3, its bottom moved by the actuator). One
//! implementation for the orchestrator's Rust loop (`workflows::hybrid::run`) and the
//! `fmu_substructure` FMU, so both integrate the same equations with the same RK4.

use serde::{Deserialize, Serialize};

/// The structure the substructures come from and the bumper's contact law.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Frame {
    pub mass: [f64; 3],
    pub damping: [f64; 3],
    pub stiffness: [f64; 3],
    /// Gap `d` of the bumper (m): it closes when `y_r = y₂ − y₃ > d`.
    pub gap: f64,
    /// Stiffness of the closed bumper (N/m).
    pub contact_stiffness: f64,
}

impl Frame {
    /// The bumper's force, one-sided: `k_nl (y_r − d)` when `y_r > d`, else 0.
    #[inline]
    pub fn contact_force(&self, yr: f64) -> f64 {
        if yr > self.gap {
            self.contact_stiffness * (yr - self.gap)
        } else {
            0.0
        }
    }

    /// Storey 3's shear with the bumper on floor 2 from above, floor 2 at `(y2, v2)`: the
    /// measured interface force `F_m = c₃ (ẏ₂ − ẏ₃) + k₃ (y₂ − y₃) + F_nl(y₂ − y₃)`.
    #[inline]
    pub fn interface_force(&self, y2: f64, v2: f64, p: &Physical) -> f64 {
        self.damping[2] * (v2 - p.v3)
            + self.stiffness[2] * (y2 - p.y3)
            + self.contact_force(y2 - p.y3)
    }
}

/// The numerical substructure's state: floors 1 and 2, loaded by the excitation on floor 1
/// and by `−F_m` on floor 2.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Numerical {
    pub y: [f64; 2],
    pub v: [f64; 2],
}

/// The physical substructure's state: floor 3 (its bottom, floor 2, is imposed).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Physical {
    pub y3: f64,
    pub v3: f64,
}

fn numerical_rate(f: &Frame, y: [f64; 2], v: [f64; 2], fe: f64, fm: f64) -> [f64; 2] {
    let [m1, m2, _] = f.mass;
    let [c1, c2, _] = f.damping;
    let [k1, k2, _] = f.stiffness;
    let storey2 = c2 * (v[1] - v[0]) + k2 * (y[1] - y[0]);
    [
        (fe - c1 * v[0] - k1 * y[0] + storey2) / m1,
        (-storey2 - fm) / m2,
    ]
}

impl Numerical {
    /// RK4 over `h`, the excitation `fe.0 + fe.1·τ` and the interface force `fm.0 + fm.1·τ`
    /// (`τ` from the step's start).
    pub fn step(&mut self, f: &Frame, h: f64, fe: (f64, f64), fm: (f64, f64)) {
        let rate = |tau: f64, y: [f64; 2], v: [f64; 2]| {
            numerical_rate(f, y, v, fe.0 + fe.1 * tau, fm.0 + fm.1 * tau)
        };
        let add = |a: [f64; 2], b: [f64; 2], k: f64| [a[0] + k * b[0], a[1] + k * b[1]];
        let (y, v) = (self.y, self.v);
        let a1 = rate(0.0, y, v);
        let (y2, v2) = (add(y, v, h / 2.0), add(v, a1, h / 2.0));
        let a2 = rate(h / 2.0, y2, v2);
        let (y3, v3) = (add(y, v2, h / 2.0), add(v, a2, h / 2.0));
        let a3 = rate(h / 2.0, y3, v3);
        let (y4, v4) = (add(y, v3, h), add(v, a3, h));
        let a4 = rate(h, y4, v4);
        for i in 0..2 {
            self.y[i] += h / 6.0 * (v[i] + 2.0 * v2[i] + 2.0 * v3[i] + v4[i]);
            self.v[i] += h / 6.0 * (a1[i] + 2.0 * a2[i] + 2.0 * a3[i] + a4[i]);
        }
    }
}

/// The imposed displacement over a step: the cubic Hermite through `(y0, v0)` at `τ = 0` and
/// `(y1, v1)` at `τ = h`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Imposed {
    pub y0: f64,
    pub v0: f64,
    pub y1: f64,
    pub v1: f64,
    pub h: f64,
}

impl Imposed {
    /// Value and rate at `τ`.
    #[inline]
    pub fn at(&self, tau: f64) -> (f64, f64) {
        let (h, s) = (self.h, tau / self.h);
        let (s2, s3) = (s * s, s * s * s);
        let y = (2.0 * s3 - 3.0 * s2 + 1.0) * self.y0
            + (s3 - 2.0 * s2 + s) * h * self.v0
            + (-2.0 * s3 + 3.0 * s2) * self.y1
            + (s3 - s2) * h * self.v1;
        let v = (6.0 * s2 - 6.0 * s) / h * self.y0
            + (3.0 * s2 - 4.0 * s + 1.0) * self.v0
            + (-6.0 * s2 + 6.0 * s) / h * self.y1
            + (3.0 * s2 - 2.0 * s) * self.v1;
        (y, v)
    }
}

impl Physical {
    /// RK4 over `[tau0, tau0 + h]` of the imposed motion (`tau0 = 0, h = imposed.h`: the whole
    /// motion in one step).
    pub fn step(&mut self, f: &Frame, h: f64, imposed: &Imposed, tau0: f64) {
        let m3 = f.mass[2];
        let rate = |tau: f64, y3: f64, v3: f64| {
            let (y2, v2) = imposed.at(tau0 + tau);
            f.interface_force(y2, v2, &Physical { y3, v3 }) / m3
        };
        let (y, v) = (self.y3, self.v3);
        let a1 = rate(0.0, y, v);
        let v2 = v + h / 2.0 * a1;
        let a2 = rate(h / 2.0, y + h / 2.0 * v, v2);
        let v3 = v + h / 2.0 * a2;
        let a3 = rate(h / 2.0, y + h / 2.0 * v2, v3);
        let v4 = v + h * a3;
        let a4 = rate(h, y + h * v3, v4);
        self.y3 += h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4);
        self.v3 += h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4);
    }

    /// The whole imposed motion in `substeps` RK4 steps.
    pub fn follow(&mut self, f: &Frame, imposed: &Imposed, substeps: u32) {
        let n = substeps.max(1);
        let hs = imposed.h / f64::from(n);
        for j in 0..n {
            self.step(f, hs, imposed, f64::from(j) * hs);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame() -> Frame {
        Frame {
            mass: [4.6, 5.3, 4.9],
            damping: [8.0, 3.5, 2.6],
            stiffness: [3850.0, 4100.0, 4650.0],
            gap: 5e-4,
            contact_stiffness: 9000.0,
        }
    }

    #[test]
    fn the_hermite_meets_its_end_conditions() {
        let m = Imposed {
            y0: 1.0,
            v0: -2.0,
            y1: 3.0,
            v1: 0.5,
            h: 0.01,
        };
        let (a, b) = (m.at(0.0), m.at(0.01));
        assert!((a.0 - 1.0).abs() < 1e-15 && (a.1 + 2.0).abs() < 1e-12);
        assert!((b.0 - 3.0).abs() < 1e-13 && (b.1 - 0.5).abs() < 1e-10);
    }

    /// Sub-stepping converges to the one-step result's limit at fourth order.
    #[test]
    fn the_physical_substeps_converge() {
        let f = Frame {
            gap: 1.0,
            ..frame()
        };
        let m = Imposed {
            y0: 0.0,
            v0: 0.05,
            y1: 1.2e-3,
            v1: 0.1,
            h: 0.02,
        };
        let run = |n| {
            let mut p = Physical::default();
            p.follow(&f, &m, n);
            p.y3
        };
        let fine = run(256);
        let (e1, e2) = ((run(4) - fine).abs(), (run(8) - fine).abs());
        assert!(e1 / e2 > 10.0, "{e1} {e2}");
    }
}
