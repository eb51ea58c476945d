//! The substructures of the simulated real-time hybrid test, as pure models, for either place
//! of the cut ([`Split`]): the numerical one (floor 1 with storeys 1 and 2, and floor 2 — the
//! twin's model of it, see [`Split::SpecimenFloors23`]) and the physical one (the specimen:
//! storey 3 with the one-sided bumper between floors 2 and 3, and floor 3, its floor 2 moved
//! by the actuator; with floor 2's mass in the paper's split). One implementation for the
//! orchestrator's Rust loop (`workflows::hybrid::run`) and the `fmu_substructure` FMU, so both
//! integrate the same equations with the same RK4.

use serde::{Deserialize, Serialize};

/// Where the structure is cut: what the physical substructure (the specimen) holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Split {
    /// The reference paper's eqs (13)–(14): floors 2 and 3 with storey 3 and the bumper are
    /// the specimen; the actuator drives floor 2, so the measured force carries floor 2's
    /// inertia, `F_m = m₂ ÿ₂ₚ + c₃ (ẏ₂ₚ − ẏ₃) + k₃ (y₂ₚ − y₃) + F_nl(y_r)`, and the numerical
    /// side (floor 1) meets it through storey 2, `F_m = c₂ (ẏ₁ − ẏ₂ₙ) + k₂ (y₁ − y₂ₙ)`.
    /// That interface equation has no mass of its own; the numerical side integrates it with
    /// the twin's floor-2 mass as a predictor whose inertia is taken back out of the load
    /// ([`floor2_load`]), so that in the limit of small steps it is eq (14) exactly.
    #[default]
    #[serde(rename = "specimen-floors-2-3")]
    SpecimenFloors23,
    /// Floor 2 on the numerical side: the specimen is storey 3 with the bumper and floor 3,
    /// moved at floor 2; `F_m = c₃ (ẏ₂ₚ − ẏ₃) + k₃ (y₂ₚ − y₃) + F_nl(y_r)` (no inertia).
    #[serde(rename = "specimen-floor-3")]
    SpecimenFloor3,
}

impl Split {
    /// Both, the default first.
    pub const ALL: [Split; 2] = [Split::SpecimenFloors23, Split::SpecimenFloor3];

    /// The name the CLI and the reports use.
    pub fn name(self) -> &'static str {
        match self {
            Split::SpecimenFloors23 => "specimen-floors-2-3",
            Split::SpecimenFloor3 => "specimen-floor-3",
        }
    }

    /// What the specimen holds, in words.
    pub fn describe(self) -> &'static str {
        match self {
            Split::SpecimenFloors23 => {
                "specimen floors 2-3 (the paper's eqs 13-14: the actuator drives floor 2 and its mass)"
            }
            Split::SpecimenFloor3 => {
                "specimen floor 3 (storey 3 moved at floor 2; floor 2's mass numerical)"
            }
        }
    }

    /// Whether floor 2's mass is in the specimen.
    pub fn floor2_physical(self) -> bool {
        self == Split::SpecimenFloors23
    }
}

impl std::fmt::Display for Split {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Split {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Split::ALL
            .into_iter()
            .find(|x| x.name() == s)
            .ok_or_else(|| {
                format!(
                    "unknown split '{s}': specimen-floors-2-3 (the paper's) or specimen-floor-3"
                )
            })
    }
}

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

    /// Storey 3's shear with the bumper on floor 2 from above, floor 2 at `(y2, v2)`:
    /// `c₃ (ẏ₂ − ẏ₃) + k₃ (y₂ − y₃) + F_nl(y₂ − y₃)` — the measured interface force of
    /// [`Split::SpecimenFloor3`].
    #[inline]
    pub fn storey3_force(&self, y2: f64, v2: f64, p: &Physical) -> f64 {
        self.damping[2] * (v2 - p.v3)
            + self.stiffness[2] * (y2 - p.y3)
            + self.contact_force(y2 - p.y3)
    }

    /// The measured interface force, floor 2 of the specimen at `(y2, v2)` with acceleration
    /// `a2`: storey 3's shear, plus floor 2's inertia `m₂ a₂` when the specimen holds floor 2.
    #[inline]
    pub fn interface_force(&self, split: Split, y2: f64, v2: f64, a2: f64, p: &Physical) -> f64 {
        let inertia = if split.floor2_physical() {
            self.mass[1] * a2
        } else {
            0.0
        };
        inertia + self.storey3_force(y2, v2, p)
    }
}

/// The load on the numerical side's floor 2 that the measured force `fm` makes, `a2n` the
/// numerical floor 2's acceleration (estimated from its displacements as the specimen's
/// motion is built, [`SampledMotion`]).
///
/// [`Split::SpecimenFloor3`]: the load is `F_m` itself. [`Split::SpecimenFloors23`]: floor 2's
/// mass is in the specimen and `F_m` carries its inertia at the motion the actuator achieved;
/// the numerical side keeps the twin's `m₂` on floor 2 as a predictor and takes its own
/// inertia back out: the load is `F_m − m₂ ÿ₂ₙ = c₃ (ẏ₂ₚ − ẏ₃) + k₃ (y₂ₚ − y₃) + F_nl +
/// m₂ (ÿ₂ₚ − ÿ₂ₙ)`, storey 3's force plus the inertia of the actuator's error. Floor 2 of the
/// numerical side then moves by `m₂ ÿ₂ₙ = S₂ − F_m + m₂ ÿ₂ₙ`, which is eq (14), `F_m = S₂`
/// (`S₂` storey 2's force on floor 2), with floor 2's inertia counted once, at the motion
/// the actuator achieved: with `y₂ₚ = (1 + a_err) y₂ₙ`, `m₂ (1 + a_err) ÿ₂ₙ = S₂ − storey 3's
/// force`. Both accelerations come from displacements by the same estimate, so with perfect
/// control the correction is zero and the loop is the other split's; under an amplitude error
/// the correction `a_err m₂ ÿ₂ₙ` feeds back a step late (stable for `|a_err|` well below 1/4 at
/// the Nyquist rate; a pure delay makes it the neutral loop of eq (14), which a stepped test
/// cannot hold).
#[inline]
pub fn floor2_load(split: Split, f: &Frame, fm: f64, a2n: f64) -> f64 {
    match split {
        Split::SpecimenFloor3 => fm,
        Split::SpecimenFloors23 => fm - f.mass[1] * a2n,
    }
}

/// A motion known by its displacements at the control steps, as a hybrid test's controller
/// knows floor 2's: the rate at each new position from the last three (second order; the
/// first from the last two), the cubic Hermite over the step, and from it the acceleration
/// at the step's end.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SampledMotion {
    /// The last position and its rate.
    pub y: f64,
    pub v: f64,
    y_previous: f64,
    steps: u64,
}

impl SampledMotion {
    /// Move to `y_new` over a control step of `h`: the motion over that step.
    pub fn advance(&mut self, y_new: f64, h: f64) -> Imposed {
        let v_end = if self.steps == 0 {
            (y_new - self.y) / h
        } else {
            (3.0 * y_new - 4.0 * self.y + self.y_previous) / (2.0 * h)
        };
        self.steps += 1;
        let motion = Imposed {
            y0: self.y,
            v0: self.v,
            y1: y_new,
            v1: v_end,
            h,
        };
        self.y_previous = self.y;
        self.y = y_new;
        self.v = v_end;
        motion
    }
}

/// The numerical substructure's state: floors 1 and 2, loaded by the excitation on floor 1
/// and by the negative of the [`floor2_load`] on floor 2 (`−F_m` when the specimen is floor 3).
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

    /// The acceleration at the motion's end (`τ = h`): what an accelerometer on the specimen's
    /// floor 2 reads at the end of a control step.
    #[inline]
    pub fn acceleration_at_end(&self) -> f64 {
        let h = self.h;
        (6.0 * (self.y0 - self.y1) + h * (2.0 * self.v0 + 4.0 * self.v1)) / (h * h)
    }
}

impl Physical {
    /// RK4 over `[tau0, tau0 + h]` of the imposed motion (`tau0 = 0, h = imposed.h`: the whole
    /// motion in one step).
    pub fn step(&mut self, f: &Frame, h: f64, imposed: &Imposed, tau0: f64) {
        let m3 = f.mass[2];
        let rate = |tau: f64, y3: f64, v3: f64| {
            let (y2, v2) = imposed.at(tau0 + tau);
            f.storey3_force(y2, v2, &Physical { y3, v3 }) / m3
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

    /// The Hermite's acceleration at its end is the derivative of its rate there (central
    /// differences of `at`, measured agreement 1e-6 relative).
    #[test]
    fn the_hermite_acceleration_is_its_rates_derivative() {
        let m = Imposed {
            y0: 1e-3,
            v0: -2e-2,
            y1: 3e-3,
            v1: 5e-2,
            h: 0.01,
        };
        let e = 1e-6;
        let numeric = (m.at(0.01 + e).1 - m.at(0.01 - e).1) / (2.0 * e);
        let exact = m.acceleration_at_end();
        assert!(
            (numeric - exact).abs() <= 1e-6 * exact.abs(),
            "{numeric} {exact}"
        );
    }

    /// Floor 2's load in the paper's split is the measured force less the numerical floor 2's
    /// inertia; in the other split the measured force itself.
    #[test]
    fn the_floor_2_load_takes_the_numerical_inertia_out() {
        let f = frame();
        let (fm, a2n) = (0.7, 0.4);
        let paper = floor2_load(Split::SpecimenFloors23, &f, fm, a2n);
        assert_eq!(paper, fm - f.mass[1] * a2n);
        assert_eq!(floor2_load(Split::SpecimenFloor3, &f, fm, a2n), fm);
    }

    /// A sampled motion's estimate of the acceleration converges on a smooth motion, at first
    /// order: the Hermite's end acceleration is second order with exact rates, but the rates
    /// from the last three positions are off by `h² y⁗/3`, which puts `−2h y⁗` in it (measured
    /// on a 19.2 Hz motion: 11.8 % and 5.9 % of its amplitude at 2048 and 4096 Hz).
    #[test]
    fn the_sampled_motion_estimates_the_acceleration() {
        let w = 2.0 * std::f64::consts::PI * 9.6;
        let error = |h: f64| {
            let mut m = SampledMotion::default();
            let mut worst = 0.0f64;
            for k in 1..=((0.5 / h) as usize) {
                let t = k as f64 * h;
                let a = m
                    .advance((w * t).sin() * (w * t).sin(), h)
                    .acceleration_at_end();
                let exact = 2.0 * w * w * (2.0 * w * t).cos();
                if t > 0.1 {
                    worst = worst.max((a - exact).abs() / (2.0 * w * w));
                }
            }
            worst
        };
        let (e1, e2) = (error(1.0 / 2048.0), error(1.0 / 4096.0));
        eprintln!("sampled acceleration error {e1:.2e} {e2:.2e}");
        assert!(e1 < 0.13 && e1 / e2 > 1.9, "{e1} {e2}");
    }

    #[test]
    fn the_splits_are_named_by_what_the_specimen_holds() {
        for split in Split::ALL {
            assert_eq!(split.name().parse::<Split>(), Ok(split));
        }
        assert_eq!(Split::default(), Split::SpecimenFloors23);
        for split in Split::ALL {
            let json = serde_json::to_string(&split).expect("json");
            assert_eq!(json, format!("\"{}\"", split.name()));
        }
        let e = "floor-2".parse::<Split>().unwrap_err();
        assert!(e.contains("specimen-floors-2-3"), "{e}");
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
