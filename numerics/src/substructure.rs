//! The substructures of the simulated real-time hybrid test, as pure models, for any shear
//! building of N storeys cut at floor j (the actuator's, 1 ≤ j < N, [`Frame`]) either way
//! ([`Split`]): the numerical one (floors 1..j, the twin's model of them) and the physical one
//! (the specimen: storeys j+1..N with the one-sided bumper in storey j+1, between floors j and
//! j+1, and floors j+1..N, moved at floor j by the actuator; with floor j's mass in the paper's
//! split). The paper's rig is N = 3, j = 2. One implementation for the orchestrator's Rust loop
//! (`workflows::hybrid::run`) and the `fmu_substructure` FMU, so both integrate the same
//! equations with the same RK4.

use serde::{Deserialize, Serialize};

/// What the specimen holds of the floor the actuator drives.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Split {
    /// The reference paper's eqs (13)–(14): floors j..N with storeys j+1..N and the bumper are
    /// the specimen; the actuator drives floor j, so the measured force carries floor j's
    /// inertia, `F_m = m_j ÿ_jp + c_{j+1} (ẏ_jp − ẏ_{j+1}) + k_{j+1} (y_jp − y_{j+1}) +
    /// F_nl(y_r)`, and the numerical side (floors 1..j−1) meets it through storey j,
    /// `F_m = c_j (ẏ_{j−1} − ẏ_jn) + k_j (y_{j−1} − y_jn)`. That interface equation has no mass
    /// of its own; the numerical side integrates it with the twin's floor-j mass as a predictor
    /// whose inertia is taken back out of the load ([`interface_load`]), so that in the limit of
    /// small steps it is eq (14) exactly.
    #[default]
    FloorPhysical,
    /// Floor j on the numerical side: the specimen is storeys j+1..N with the bumper and
    /// floors j+1..N, moved at floor j; `F_m = c_{j+1} (ẏ_jp − ẏ_{j+1}) + k_{j+1} (y_jp −
    /// y_{j+1}) + F_nl(y_r)` (no inertia).
    FloorNumerical,
}

impl Split {
    /// Both, the default first.
    pub const ALL: [Split; 2] = [Split::FloorPhysical, Split::FloorNumerical];

    /// Whether the driven floor's mass is in the specimen.
    pub fn floor_physical(self) -> bool {
        self == Split::FloorPhysical
    }
}

/// Where a structure is cut, as `--split` and the reports name it: the floor j the actuator
/// drives and what the specimen holds ([`Split`]).
///
/// Names: `J` (the paper's split at floor J); `specimen-floors-J-N` (the same, the storey
/// count stated: the specimen is floors J..N with floor J's mass); `specimen-storeys-A-N` (the
/// specimen is storeys A..N and floors A..N, moved at floor A − 1, which stays numerical),
/// written `specimen-floor-N` when A = N. The paper's rig: `specimen-floors-2-3` (the default)
/// and `specimen-floor-3`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Cut {
    /// j.
    pub floor: usize,
    pub split: Split,
    /// The storey count the name states, if it states one.
    pub storeys: Option<usize>,
}

impl Cut {
    /// The paper's split at floor `floor`.
    pub fn at(floor: usize) -> Cut {
        Cut {
            floor,
            split: Split::FloorPhysical,
            storeys: None,
        }
    }

    /// The name of this cut of an N-storey structure.
    pub fn name(&self, storeys: usize) -> String {
        let j = self.floor;
        match self.split {
            Split::FloorPhysical => format!("specimen-floors-{j}-{storeys}"),
            Split::FloorNumerical if j + 1 == storeys => format!("specimen-floor-{storeys}"),
            Split::FloorNumerical => format!("specimen-storeys-{}-{storeys}", j + 1),
        }
    }

    /// What the specimen holds, in words, for an N-storey structure.
    pub fn describe(&self, storeys: usize) -> String {
        let j = self.floor;
        let floors = |a: usize| {
            if a == storeys {
                format!("floor {a}")
            } else {
                format!("floors {a}-{storeys}")
            }
        };
        match self.split {
            Split::FloorPhysical => format!(
                "specimen {} (the paper's eqs 13-14: the actuator drives floor {j} and its mass)",
                floors(j)
            ),
            Split::FloorNumerical => format!(
                "specimen {} (storey {} moved at floor {j}; floor {j}'s mass numerical)",
                floors(j + 1),
                j + 1
            ),
        }
    }
}

impl std::fmt::Display for Cut {
    /// Its name when it states the storey count, else the floor.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.storeys {
            Some(n) => f.write_str(&self.name(n)),
            None => write!(f, "{}", self.floor),
        }
    }
}

impl std::str::FromStr for Cut {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || {
            format!(
                "unknown split '{s}': give the floor the actuator drives (e.g. 2, the paper's split: the \
                 specimen that floor and those above) or a name: specimen-floors-J-N, \
                 specimen-storeys-A-N or specimen-floor-N"
            )
        };
        let number = |t: &str| t.parse::<usize>().map_err(|_| bad());
        if let Ok(j) = s.parse::<usize>() {
            return Ok(Cut::at(j));
        }
        let two = |rest: &str| -> Result<(usize, usize), String> {
            let (a, b) = rest.split_once('-').ok_or_else(bad)?;
            Ok((number(a)?, number(b)?))
        };
        let (floor, split, storeys) = if let Some(rest) = s.strip_prefix("specimen-floors-") {
            let (a, n) = two(rest)?;
            (a, Split::FloorPhysical, n)
        } else if let Some(rest) = s.strip_prefix("specimen-storeys-") {
            let (a, n) = two(rest)?;
            (a.checked_sub(1).ok_or_else(bad)?, Split::FloorNumerical, n)
        } else if let Some(rest) = s.strip_prefix("specimen-floor-") {
            let n = number(rest)?;
            (n.checked_sub(1).ok_or_else(bad)?, Split::FloorNumerical, n)
        } else {
            return Err(bad());
        };
        Ok(Cut {
            floor,
            split,
            storeys: Some(storeys),
        })
    }
}

/// The structure the substructures come from, where it is cut, and the bumper's contact law.
///
/// Floor `j = floor` is the one the actuator drives (1 ≤ j < N): the numerical substructure
/// holds floors 1..j (floor j's model as the predictor of [`interface_load`] when the specimen
/// holds its mass), the physical one storeys j+1..N and floors j+1..N, with the bumper in
/// storey j+1 (between floors j and j+1), and floor j's mass in [`Split::FloorPhysical`]. The
/// paper's rig is N = 3, j = 2.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Frame {
    /// kg, floors 1..N.
    pub mass: Vec<f64>,
    /// N s/m, storeys 1..N.
    pub damping: Vec<f64>,
    /// N/m, storeys 1..N.
    pub stiffness: Vec<f64>,
    /// The floor the actuator drives, j.
    pub floor: usize,
    /// Gap `d` of the bumper (m): it closes when `y_r = y_j − y_{j+1} > d`.
    pub gap: f64,
    /// Stiffness of the closed bumper (N/m).
    pub contact_stiffness: f64,
}

impl Frame {
    /// The storey count N.
    pub fn storeys(&self) -> usize {
        self.mass.len()
    }

    /// Why the frame cannot be cut, if it cannot: the three vectors of one length N ≥ 2, every
    /// value finite, masses, stiffnesses and the gap positive, dampings and the contact
    /// stiffness non-negative, and 1 ≤ floor < N (the specimen holds at least the storey with
    /// the bumper above the driven floor).
    pub fn check(&self) -> Result<(), String> {
        let n = self.storeys();
        if self.damping.len() != n || self.stiffness.len() != n {
            return Err(format!(
                "{} masses, {} dampings and {} stiffnesses: one per floor / storey",
                n,
                self.damping.len(),
                self.stiffness.len()
            ));
        }
        for i in 0..n {
            for (name, value, strict) in [
                ("m", self.mass[i], true),
                ("c", self.damping[i], false),
                ("k", self.stiffness[i], true),
            ] {
                if !value.is_finite() || value < 0.0 || (strict && value == 0.0) {
                    return Err(format!(
                        "{name}{} must be {} and finite, was {value}",
                        i + 1,
                        if strict { "positive" } else { "non-negative" }
                    ));
                }
            }
        }
        if n < 2 {
            return Err(format!(
                "a {n}-storey structure cannot be split: the actuator drives a floor with a \
                 storey above it"
            ));
        }
        if !(1..n).contains(&self.floor) {
            return Err(format!(
                "the actuator's floor {} of a {n}-storey structure: it must be 1 to {} (the \
                 specimen holds the storey above it, with the bumper)",
                self.floor,
                n - 1
            ));
        }
        if !(self.gap.is_finite() && self.gap > 0.0) {
            return Err(format!(
                "the gap must be positive and finite, was {}",
                self.gap
            ));
        }
        if !(self.contact_stiffness.is_finite() && self.contact_stiffness >= 0.0) {
            return Err(format!(
                "the contact stiffness must be non-negative and finite, was {}",
                self.contact_stiffness
            ));
        }
        Ok(())
    }

    /// The bumper's force, one-sided: `k_nl (y_r − d)` when `y_r > d`, else 0.
    #[inline]
    pub fn contact_force(&self, yr: f64) -> f64 {
        if yr > self.gap {
            self.contact_stiffness * (yr - self.gap)
        } else {
            0.0
        }
    }

    /// Storey j+1's shear with the bumper on floor j from above, floor j at `(yj, vj)`:
    /// `c_{j+1} (ẏ_j − ẏ_{j+1}) + k_{j+1} (y_j − y_{j+1}) + F_nl(y_j − y_{j+1})` — the measured
    /// interface force of [`Split::FloorNumerical`].
    #[inline]
    pub fn storey_above_force(&self, yj: f64, vj: f64, p: &Physical) -> f64 {
        let s = self.floor;
        self.damping[s] * (vj - p.v[0])
            + self.stiffness[s] * (yj - p.y[0])
            + self.contact_force(yj - p.y[0])
    }

    /// The measured interface force, floor j of the specimen at `(yj, vj)` with acceleration
    /// `aj`: storey j+1's shear, plus floor j's inertia `m_j a_j` when the specimen holds floor j.
    #[inline]
    pub fn interface_force(&self, split: Split, yj: f64, vj: f64, aj: f64, p: &Physical) -> f64 {
        let inertia = if split.floor_physical() {
            self.mass[self.floor - 1] * aj
        } else {
            0.0
        };
        inertia + self.storey_above_force(yj, vj, p)
    }
}

/// The load on the numerical side's floor j that the measured force `fm` makes, `ajn` the
/// numerical floor j's acceleration (estimated from its displacements as the specimen's
/// motion is built, [`SampledMotion`]).
///
/// [`Split::FloorNumerical`]: the load is `F_m` itself. [`Split::FloorPhysical`]: floor j's
/// mass is in the specimen and `F_m` carries its inertia at the motion the actuator achieved;
/// the numerical side keeps the twin's `m_j` on floor j as a predictor and takes its own
/// inertia back out: the load is `F_m − m_j ÿ_jn = (storey j+1's force) + m_j (ÿ_jp − ÿ_jn)`,
/// storey j+1's force plus the inertia of the actuator's error. Floor j of the numerical side
/// then moves by `m_j ÿ_jn = S_j − F_m + m_j ÿ_jn`, which is the paper's eq (14), `F_m = S_j`
/// (`S_j` the forces of the numerical side on floor j), with floor j's inertia counted once, at
/// the motion the actuator achieved: with `y_jp = (1 + a_err) y_jn`, `m_j (1 + a_err) ÿ_jn =
/// S_j − storey j+1's force`. Both accelerations come from displacements by the same
/// estimate, so with perfect control the correction is zero and the loop is the other split's;
/// under an amplitude error the correction `a_err m_j ÿ_jn` feeds back a step late (stable for
/// `|a_err|` well below 1/4 at the Nyquist rate; a pure delay makes it the neutral loop of eq
/// (14), which a stepped test cannot hold).
#[inline]
pub fn interface_load(split: Split, f: &Frame, fm: f64, ajn: f64) -> f64 {
    match split {
        Split::FloorNumerical => fm,
        Split::FloorPhysical => fm - f.mass[f.floor - 1] * ajn,
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

/// The numerical substructure's state: floors 1..j, loaded by the excitation on floor 1 and by
/// the negative of the [`interface_load`] on floor j (`−F_m` with floor j numerical).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Numerical {
    pub y: Vec<f64>,
    pub v: Vec<f64>,
}

/// The physical substructure's state: floors j+1..N (its bottom, floor j, is imposed).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Physical {
    pub y: Vec<f64>,
    pub v: Vec<f64>,
}

/// The accelerations of the numerical floors 1..j at `(y, v)` under the excitation `fe` on
/// floor 1 and the load `fm` on floor j, into `a`.
fn numerical_rate(f: &Frame, y: &[f64], v: &[f64], fe: f64, fm: f64, a: &mut [f64]) {
    let j = y.len();
    // Storey i + 1's extension force on floor i (0-based): c (v_i − v_{i−1}) + k (y_i − y_{i−1}).
    let storey = |i: usize| f.damping[i] * (v[i] - v[i - 1]) + f.stiffness[i] * (y[i] - y[i - 1]);
    for i in 0..j {
        let below = if i == 0 {
            fe - f.damping[0] * v[0] - f.stiffness[0] * y[0]
        } else {
            -storey(i)
        };
        let total = if i + 1 < j {
            below + storey(i + 1)
        } else {
            below - fm
        };
        a[i] = total / f.mass[i];
    }
}

/// `a + k b`, elementwise.
fn axpy(a: &[f64], b: &[f64], k: f64) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x + k * y).collect()
}

impl Numerical {
    /// At rest, floors 1..j of `f`.
    pub fn at_rest(f: &Frame) -> Numerical {
        Numerical {
            y: vec![0.0; f.floor],
            v: vec![0.0; f.floor],
        }
    }

    /// RK4 over `h`, the excitation `fe.0 + fe.1·τ` and the interface force `fm.0 + fm.1·τ`
    /// (`τ` from the step's start).
    pub fn step(&mut self, f: &Frame, h: f64, fe: (f64, f64), fm: (f64, f64)) {
        let n = self.y.len();
        let rate = |tau: f64, y: &[f64], v: &[f64]| {
            let mut a = vec![0.0; n];
            numerical_rate(f, y, v, fe.0 + fe.1 * tau, fm.0 + fm.1 * tau, &mut a);
            a
        };
        let (y, v) = (&self.y.clone(), &self.v.clone());
        let a1 = rate(0.0, y, v);
        let (y2, v2) = (axpy(y, v, h / 2.0), axpy(v, &a1, h / 2.0));
        let a2 = rate(h / 2.0, &y2, &v2);
        let (y3, v3) = (axpy(y, &v2, h / 2.0), axpy(v, &a2, h / 2.0));
        let a3 = rate(h / 2.0, &y3, &v3);
        let (y4, v4) = (axpy(y, &v3, h), axpy(v, &a3, h));
        let a4 = rate(h, &y4, &v4);
        for i in 0..n {
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

/// The accelerations of the physical floors j+1..N at `(y, v)`, floor j at `(yj, vj)`, into `a`.
fn physical_rate(f: &Frame, yj: f64, vj: f64, y: &[f64], v: &[f64], a: &mut [f64]) {
    let n = y.len();
    let s = f.floor;
    // Storey s + p + 1's force on floor s + p + 1 from below (0-based floor s + p), the bumper's
    // in the first.
    let from_below = |p: usize| {
        if p == 0 {
            f.damping[s] * (vj - v[0]) + f.stiffness[s] * (yj - y[0]) + f.contact_force(yj - y[0])
        } else {
            f.damping[s + p] * (v[p - 1] - v[p]) + f.stiffness[s + p] * (y[p - 1] - y[p])
        }
    };
    let mut below = from_below(0);
    for p in 0..n {
        let total = if p + 1 < n {
            let above = from_below(p + 1);
            let t = below - above;
            below = above;
            t
        } else {
            below
        };
        a[p] = total / f.mass[s + p];
    }
}

impl Physical {
    /// At rest, floors j+1..N of `f`.
    pub fn at_rest(f: &Frame) -> Physical {
        let n = f.storeys().saturating_sub(f.floor);
        Physical {
            y: vec![0.0; n],
            v: vec![0.0; n],
        }
    }

    /// RK4 over `[tau0, tau0 + h]` of the imposed motion (`tau0 = 0, h = imposed.h`: the whole
    /// motion in one step).
    pub fn step(&mut self, f: &Frame, h: f64, imposed: &Imposed, tau0: f64) {
        let n = self.y.len();
        let rate = |tau: f64, y: &[f64], v: &[f64]| {
            let (yj, vj) = imposed.at(tau0 + tau);
            let mut a = vec![0.0; n];
            physical_rate(f, yj, vj, y, v, &mut a);
            a
        };
        let (y, v) = (&self.y.clone(), &self.v.clone());
        let a1 = rate(0.0, y, v);
        let v2 = axpy(v, &a1, h / 2.0);
        let a2 = rate(h / 2.0, &axpy(y, v, h / 2.0), &v2);
        let v3 = axpy(v, &a2, h / 2.0);
        let a3 = rate(h / 2.0, &axpy(y, &v2, h / 2.0), &v3);
        let v4 = axpy(v, &a3, h);
        let a4 = rate(h, &axpy(y, &v3, h), &v4);
        for i in 0..n {
            self.y[i] += h / 6.0 * (v[i] + 2.0 * v2[i] + 2.0 * v3[i] + v4[i]);
            self.v[i] += h / 6.0 * (a1[i] + 2.0 * a2[i] + 2.0 * a3[i] + a4[i]);
        }
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
            mass: vec![4.6, 5.3, 4.9],
            damping: vec![8.0, 3.5, 2.6],
            stiffness: vec![3850.0, 4100.0, 4650.0],
            floor: 2,
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

    /// Floor j's load in the paper's split is the measured force less the numerical floor j's
    /// inertia; in the other split the measured force itself.
    #[test]
    fn the_floor_j_load_takes_the_numerical_inertia_out() {
        let f = frame();
        let (fm, a2n) = (0.7, 0.4);
        let paper = interface_load(Split::FloorPhysical, &f, fm, a2n);
        assert_eq!(paper, fm - f.mass[1] * a2n);
        assert_eq!(interface_load(Split::FloorNumerical, &f, fm, a2n), fm);
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

    /// The paper's names parse to its cuts and back; a cut at floor J names the storey count;
    /// a name that is none is refused with the forms it could take.
    #[test]
    fn the_cuts_are_named_by_what_the_specimen_holds() {
        let paper: Cut = "specimen-floors-2-3".parse().expect("paper");
        assert_eq!((paper.floor, paper.split), (2, Split::FloorPhysical));
        assert_eq!(paper.name(3), "specimen-floors-2-3");
        let other: Cut = "specimen-floor-3".parse().expect("other");
        assert_eq!((other.floor, other.split), (2, Split::FloorNumerical));
        assert_eq!(other.name(3), "specimen-floor-3");
        let three: Cut = "3".parse().expect("floor");
        assert_eq!(
            (three.floor, three.split, three.storeys),
            (3, Split::FloorPhysical, None)
        );
        assert_eq!(three.name(5), "specimen-floors-3-5");
        let storeys: Cut = "specimen-storeys-4-5".parse().expect("storeys");
        assert_eq!((storeys.floor, storeys.split), (3, Split::FloorNumerical));
        assert_eq!(storeys.name(5), "specimen-storeys-4-5");
        for name in [
            "specimen-floors-1-4",
            "specimen-storeys-2-4",
            "specimen-floor-4",
        ] {
            let cut: Cut = name.parse().expect(name);
            assert_eq!(cut.name(4), name);
        }
        for bad in ["floor-2", "specimen-floors-2", "specimen-floor-0", "-1"] {
            let e = bad.parse::<Cut>().unwrap_err();
            assert!(e.contains("specimen-floors-J-N"), "{e}");
        }
        assert_eq!(Split::default(), Split::FloorPhysical);
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
            let mut p = Physical::at_rest(&f);
            p.follow(&f, &m, n);
            p.y[0]
        };
        let fine = run(256);
        let (e1, e2) = ((run(4) - fine).abs(), (run(8) - fine).abs());
        assert!(e1 / e2 > 10.0, "{e1} {e2}");
    }
}
