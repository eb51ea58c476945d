//! [`Structure`]: storeys, masses, dampings, stiffnesses and the excitation.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// The most storeys a structure may have. The FMU lays out its variables by storey, and a
/// diagnosis visits every storey; 50 is well past the 20 the product promises.
pub const MAX_STOREYS: usize = 50;

/// What shakes the building.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Excitation {
    /// A force (N) on floor `floor` (1-based): a shaker.
    Force { floor: usize },
    /// Ground acceleration (m/s²) at the base: an earthquake or a shaking table.
    Base,
}

impl Default for Excitation {
    /// The reference paper's shaker on floor 1.
    fn default() -> Self {
        crate::paper::EXCITATION
    }
}

impl Excitation {
    /// `force:K` or `base` (as `twin init --excitation` takes it).
    pub fn parse(text: &str) -> Result<Excitation, StructureError> {
        let bad = || StructureError::Excitation(text.to_owned());
        match text.trim() {
            "base" => Ok(Excitation::Base),
            t => {
                let floor = t.strip_prefix("force:").ok_or_else(bad)?;
                let floor: usize = floor.trim().parse().map_err(|_| bad())?;
                if floor == 0 {
                    return Err(bad());
                }
                Ok(Excitation::Force { floor })
            }
        }
    }

    /// The inverse of [`Excitation::parse`].
    pub fn name(&self) -> String {
        match self {
            Excitation::Force { floor } => format!("force:{floor}"),
            Excitation::Base => "base".to_owned(),
        }
    }

    /// The record's column (and the FMU's input) carrying it: `force` or `ground_acc`.
    pub fn input_name(&self) -> &'static str {
        match self {
            Excitation::Force { .. } => "force",
            Excitation::Base => "ground_acc",
        }
    }

    /// In words: "a force at floor 2", "ground acceleration at the base".
    pub fn describe(&self) -> String {
        match self {
            Excitation::Force { floor } => format!("a force at floor {floor}"),
            Excitation::Base => "ground acceleration at the base".to_owned(),
        }
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StructureError {
    #[error("a structure has 1 to {MAX_STOREYS} storeys, not {0}")]
    Storeys(usize),
    #[error("{what} has {got} values; the structure has {storeys} storeys")]
    Length {
        what: &'static str,
        got: usize,
        storeys: usize,
    },
    #[error("{name} = {value}: {rule}")]
    Value {
        name: String,
        value: f64,
        rule: &'static str,
    },
    #[error("the excitation '{0}' is neither 'force:K' (K a floor, 1-based) nor 'base'")]
    Excitation(String),
    #[error("the force is at floor {floor}; the structure has floors 1 to {storeys}")]
    ForceFloor { floor: usize, storeys: usize },
}

/// A shear building: per floor its mass, per storey its damping and stiffness, and what excites
/// it. Index i of each vector is floor / storey i + 1.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Structure {
    /// kg, floors 1..N.
    pub mass: Vec<f64>,
    /// N s/m, storeys 1..N.
    pub damping: Vec<f64>,
    /// N/m, storeys 1..N.
    pub stiffness: Vec<f64>,
    #[serde(default)]
    pub excitation: Excitation,
}

impl Default for Structure {
    /// The reference paper's three-storey frame at its prior means, shaken at floor 1.
    fn default() -> Self {
        crate::paper::structure()
    }
}

impl Structure {
    /// `storeys` equal floors and storeys.
    pub fn uniform(
        storeys: usize,
        mass: f64,
        damping: f64,
        stiffness: f64,
        excitation: Excitation,
    ) -> Structure {
        Structure {
            mass: vec![mass; storeys],
            damping: vec![damping; storeys],
            stiffness: vec![stiffness; storeys],
            excitation,
        }
    }

    pub fn storeys(&self) -> usize {
        self.mass.len()
    }

    /// The sizes agree, 1 ≤ N ≤ [`MAX_STOREYS`], every value finite, masses and stiffnesses
    /// positive, dampings non-negative, the force at a floor the structure has.
    pub fn validate(&self) -> Result<(), StructureError> {
        let n = self.storeys();
        if n == 0 || n > MAX_STOREYS {
            return Err(StructureError::Storeys(n));
        }
        for (what, v) in [("damping", &self.damping), ("stiffness", &self.stiffness)] {
            if v.len() != n {
                return Err(StructureError::Length {
                    what,
                    got: v.len(),
                    storeys: n,
                });
            }
        }
        for (name, value) in self.parameter_names().into_iter().zip(self.parameters()) {
            let damping = name.starts_with('c');
            let ok = value.is_finite() && if damping { value >= 0.0 } else { value > 0.0 };
            if !ok {
                return Err(StructureError::Value {
                    name,
                    value,
                    rule: if damping {
                        "a damping must be finite and non-negative"
                    } else {
                        "must be finite and positive"
                    },
                });
            }
        }
        if let Excitation::Force { floor } = self.excitation {
            if floor == 0 || floor > n {
                return Err(StructureError::ForceFloor { floor, storeys: n });
            }
        }
        Ok(())
    }

    /// `m1..mN, c1..cN, k1..kN`: the FMU's parameter names, in [`Structure::parameters`]'s order.
    pub fn parameter_names(&self) -> Vec<String> {
        parameter_names(self.storeys())
    }

    /// The masses, then the dampings, then the stiffnesses.
    pub fn parameters(&self) -> Vec<f64> {
        self.mass
            .iter()
            .chain(&self.damping)
            .chain(&self.stiffness)
            .copied()
            .collect()
    }

    /// Sets a parameter by its name (`m2`, `k10`); `false` when the structure has no such one.
    pub fn set(&mut self, name: &str, value: f64) -> bool {
        match self.parameter_mut(name) {
            Some(p) => {
                *p = value;
                true
            }
            None => false,
        }
    }

    /// A parameter by its name (`m2`, `k10`).
    pub fn get(&self, name: &str) -> Option<f64> {
        let (vector, index) = self.locate(name)?;
        Some(vector[index])
    }

    fn locate(&self, name: &str) -> Option<(&Vec<f64>, usize)> {
        let (vector, index) = split_parameter(name)?;
        let v = match vector {
            'm' => &self.mass,
            'c' => &self.damping,
            _ => &self.stiffness,
        };
        (index < v.len()).then_some((v, index))
    }

    fn parameter_mut(&mut self, name: &str) -> Option<&mut f64> {
        let (vector, index) = split_parameter(name)?;
        let v = match vector {
            'm' => &mut self.mass,
            'c' => &mut self.damping,
            _ => &mut self.stiffness,
        };
        v.get_mut(index)
    }

    pub fn mass_matrix(&self) -> DMatrix<f64> {
        DMatrix::from_diagonal(&DVector::from_column_slice(&self.mass))
    }

    pub fn damping_matrix(&self) -> DMatrix<f64> {
        storey_matrix(&self.damping)
    }

    pub fn stiffness_matrix(&self) -> DMatrix<f64> {
        storey_matrix(&self.stiffness)
    }

    /// The load vector `L` of `M ÿ + C ẏ + K y = L u`: `e_K` for a force at floor K (u in N),
    /// `−M 1` for ground acceleration (u in m/s²).
    pub fn load_vector(&self) -> DVector<f64> {
        let n = self.storeys();
        match self.excitation {
            Excitation::Force { floor } => {
                let mut l = DVector::zeros(n);
                if (1..=n).contains(&floor) {
                    l[floor - 1] = 1.0;
                }
                l
            }
            Excitation::Base => DVector::from_iterator(n, self.mass.iter().map(|m| -m)),
        }
    }

    /// A force (N) at `floor` (1-based), whatever excites the building (an actuator): its
    /// column in `ẋ = A x + …` of [`Structure::state_space`] and its feedthrough into the
    /// accelerometers' reading, `(M⁻¹ e_floor` below the displacements, `M⁻¹ e_floor)`.
    pub fn force_input(
        &self,
        floor: usize,
    ) -> Result<(DVector<f64>, DVector<f64>), StructureError> {
        let n = self.storeys();
        if floor == 0 || floor > n {
            return Err(StructureError::ForceFloor { floor, storeys: n });
        }
        let mut d = DVector::zeros(n);
        d[floor - 1] = 1.0 / self.mass[floor - 1];
        let mut b = DVector::zeros(2 * n);
        b[n + floor - 1] = d[floor - 1];
        Ok((b, d))
    }

    /// Undamped natural frequencies, Hz, ascending.
    pub fn natural_frequencies(&self) -> Vec<f64> {
        let s = DMatrix::from_diagonal(&DVector::from_iterator(
            self.storeys(),
            self.mass.iter().map(|m| 1.0 / m.sqrt()),
        ));
        let sym = &s * self.stiffness_matrix() * &s;
        let mut f: Vec<f64> = sym
            .symmetric_eigenvalues()
            .iter()
            .map(|&l| l.max(0.0).sqrt() / (2.0 * std::f64::consts::PI))
            .collect();
        f.sort_by(f64::total_cmp);
        f
    }

    /// The linear model as `ẋ = A x + B u` with `x = (y, ẏ)` (relative displacements, then
    /// velocities) and the accelerometers' reading `ÿ_abs = C x + D u` (absolute: `ÿ + a_g` under
    /// ground motion).
    pub fn state_space(&self) -> Result<StateSpace, StructureError> {
        self.validate()?;
        let n = self.storeys();
        let m_inv = DMatrix::from_diagonal(&DVector::from_iterator(
            n,
            self.mass.iter().map(|m| 1.0 / m),
        ));
        let mk = -(&m_inv * self.stiffness_matrix());
        let mc = -(&m_inv * self.damping_matrix());
        let ml = &m_inv * self.load_vector();
        let mut a = DMatrix::zeros(2 * n, 2 * n);
        let mut c = DMatrix::zeros(n, 2 * n);
        let mut b = DVector::zeros(2 * n);
        for i in 0..n {
            a[(i, n + i)] = 1.0;
            b[n + i] = ml[i];
            for j in 0..n {
                a[(n + i, j)] = mk[(i, j)];
                a[(n + i, n + j)] = mc[(i, j)];
                c[(i, j)] = mk[(i, j)];
                c[(i, n + j)] = mc[(i, j)];
            }
        }
        // Under ground motion ÿ = … − a_g, and the accelerometer adds a_g back.
        let d = match self.excitation {
            Excitation::Force { .. } => ml,
            Excitation::Base => DVector::zeros(n),
        };
        Ok(StateSpace { a, b, c, d })
    }
}

/// `m1..mN, c1..cN, k1..kN` for `storeys` storeys.
pub fn parameter_names(storeys: usize) -> Vec<String> {
    ['m', 'c', 'k']
        .iter()
        .flat_map(|p| (1..=storeys).map(move |i| format!("{p}{i}")))
        .collect()
}

/// `m3` → ('m', 2); `None` for anything else.
fn split_parameter(name: &str) -> Option<(char, usize)> {
    let mut chars = name.chars();
    let vector = chars.next().filter(|c| matches!(c, 'm' | 'c' | 'k'))?;
    let digits = chars.as_str();
    if digits.is_empty() || digits.starts_with('0') || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let floor: usize = digits.parse().ok()?;
    Some((vector, floor - 1))
}

/// The tridiagonal matrix of storey coefficients (storey i joins floor i − 1 and floor i).
fn storey_matrix(c: &[f64]) -> DMatrix<f64> {
    let n = c.len();
    let mut m = DMatrix::zeros(n, n);
    for i in 0..n {
        m[(i, i)] += c[i];
        if i + 1 < n {
            m[(i, i)] += c[i + 1];
            m[(i, i + 1)] -= c[i + 1];
            m[(i + 1, i)] -= c[i + 1];
        }
    }
    m
}

/// `ẋ = A x + B u`, `ÿ_abs = C x + D u`, `x = (y, ẏ)` in metres and m/s.
#[derive(Clone, Debug, PartialEq)]
pub struct StateSpace {
    pub a: DMatrix<f64>,
    pub b: DVector<f64>,
    pub c: DMatrix<f64>,
    pub d: DVector<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_is_the_papers_rig() {
        let s = Structure::default();
        assert_eq!(s.storeys(), 3);
        assert_eq!(s.excitation, Excitation::Force { floor: 1 });
        assert_eq!(s.mass, vec![5.2; 3]);
        assert_eq!(
            s.parameter_names(),
            ["m1", "m2", "m3", "c1", "c2", "c3", "k1", "k2", "k3"]
        );
        s.validate().unwrap();
    }

    #[test]
    fn excitation_round_trips_and_refuses_nonsense() {
        for text in ["force:1", "force:7", "base"] {
            assert_eq!(Excitation::parse(text).unwrap().name(), text);
        }
        for text in ["force:0", "force:", "force:x", "ground", ""] {
            assert!(Excitation::parse(text).is_err(), "{text}");
        }
    }

    #[test]
    fn validation_names_the_value() {
        let mut s = Structure::uniform(5, 1.0, 0.1, 100.0, Excitation::Force { floor: 6 });
        assert_eq!(
            s.validate(),
            Err(StructureError::ForceFloor {
                floor: 6,
                storeys: 5
            })
        );
        s.excitation = Excitation::Base;
        s.validate().unwrap();
        assert!(s.set("k4", -1.0));
        let e = s.validate().unwrap_err().to_string();
        assert!(e.starts_with("k4 = -1"), "{e}");
        assert!(!s.set("k6", 1.0));
        assert!(!s.set("k0", 1.0));
        assert!(!s.set("x1", 1.0));
        assert_eq!(s.get("k4"), Some(-1.0));
        assert!(Structure::uniform(0, 1.0, 0.0, 1.0, Excitation::Base)
            .validate()
            .is_err());
    }

    #[test]
    fn stiffness_matrix_is_the_tridiagonal_shear_matrix() {
        let mut s = Structure::uniform(3, 1.0, 0.0, 0.0, Excitation::Base);
        s.stiffness = vec![1.0, 2.0, 4.0];
        let k = s.stiffness_matrix();
        let want =
            DMatrix::from_row_slice(3, 3, &[3.0, -2.0, 0.0, -2.0, 6.0, -4.0, 0.0, -4.0, 4.0]);
        assert_eq!(k, want);
    }

    /// The natural frequencies of three equal storeys: 2√(k/m)·sin((2i−1)π/14) rad/s.
    #[test]
    fn natural_frequencies_of_a_uniform_frame() {
        let f = Structure::uniform(3, 5.2, 0.5, 4021.0, Excitation::Base).natural_frequencies();
        let w0 = (4021.0f64 / 5.2).sqrt();
        for (i, fi) in f.iter().enumerate() {
            let expected = 2.0 * w0 * ((2 * i + 1) as f64 * std::f64::consts::PI / 14.0).sin()
                / (2.0 * std::f64::consts::PI);
            assert!(
                (fi - expected).abs() < 1e-9 * expected,
                "{fi} vs {expected}"
            );
        }
    }

    /// A force at floor K is the shaker's input when the shaker is at K; elsewhere it is refused.
    #[test]
    fn a_force_input_at_the_excitations_floor_is_the_excitations() {
        let s = Structure::uniform(4, 2.0, 0.1, 100.0, Excitation::Force { floor: 3 });
        let ss = s.state_space().unwrap();
        let (b, d) = s.force_input(3).unwrap();
        assert_eq!((b, d), (ss.b, ss.d));
        let (b, d) = s.force_input(1).unwrap();
        assert_eq!(b[4], 0.5);
        assert_eq!(b.iter().filter(|x| **x != 0.0).count(), 1);
        assert_eq!(d[0], 0.5);
        assert!(s.force_input(0).is_err() && s.force_input(5).is_err());
    }

    #[test]
    fn one_storey_frequency_is_the_oscillators() {
        let s = Structure::uniform(1, 2.0, 0.0, 800.0, Excitation::Base);
        let f = s.natural_frequencies();
        let want = (800.0f64 / 2.0).sqrt() / (2.0 * std::f64::consts::PI);
        assert!((f[0] - want).abs() < 1e-12 * want);
    }

    #[test]
    fn ground_motion_moves_a_rigid_building_with_the_ground() {
        // A very stiff building under a_g: relative motion vanishes, the accelerometers read a_g.
        let s = Structure::uniform(4, 3.0, 1.0, 1e12, Excitation::Base);
        let ss = s.state_space().unwrap();
        // Static response to u = 1: A x + B = 0 with ẏ = 0 → y = K⁻¹ (−M 1).
        let n = 4;
        let k = s.stiffness_matrix();
        let y = k.lu().solve(&s.load_vector()).unwrap();
        let mut x = DVector::zeros(2 * n);
        x.rows_mut(0, n).copy_from(&y);
        // At rest relative to the ground the absolute reading is a_g: C x = M⁻¹(−K y) = 1.
        let acc = &ss.c * &x + &ss.d * 1.0;
        for i in 0..n {
            assert!((acc[i] - 1.0).abs() < 1e-9, "{acc}");
        }
    }
}
