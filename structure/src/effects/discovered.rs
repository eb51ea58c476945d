//! A generic "discovered" effect: terms `coefficient · f(x, v)`, each a candidate function `f`
//! of one site's displacement-like `x` and velocity-like `v`; the shear FMU carries a few of them
//! with the function, the site and the numbers as parameters. A missing force found by sparse
//! regression over the candidates is then a parameter set of the same FMU, which any FMI host
//! (fmpy included) runs.
//!
//! At a storey site `x` is the storey's drift `y_s − y_{s−1}` (ground `y_0 = 0`) and `v` its
//! rate; the force is a storey force (positive resists a positive drift, [`add_storey_force`]).
//! At a floor site `x` and `v` are the floor's displacement and velocity and the force acts on
//! that floor alone, like a spring or damper to the ground. Sign convention as the rest of the
//! library: the force adds to `g` on the left-hand side, so a positive coefficient on `x` is
//! extra stiffness and on `v` extra damping.
//!
//! Here: the functions, the sites of a building of N storeys, a term and its force, and the
//! names of a term's parameters (`discovered{i}_{suffix}`); the FMU's value references and
//! storage are the shear FMU's.

use std::fmt;

use serde::{Deserialize, Serialize};

use super::label::Location;
use super::{add_storey_force, drift, InvalidParameter};

/// The parameters of one term, in value-reference order (the discriminant is the slot's offset
/// in the term's block of value references).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    Enabled = 0,
    Function = 1,
    Placement = 2,
    At = 3,
    Coefficient = 4,
    Scale = 5,
}

impl Slot {
    pub const ALL: [Slot; 6] = [
        Slot::Enabled,
        Slot::Function,
        Slot::Placement,
        Slot::At,
        Slot::Coefficient,
        Slot::Scale,
    ];

    pub fn suffix(self) -> &'static str {
        match self {
            Slot::Enabled => "enabled",
            Slot::Function => "function",
            Slot::Placement => "placement",
            Slot::At => "at",
            Slot::Coefficient => "coefficient",
            Slot::Scale => "scale",
        }
    }

    /// The slot at offset `index` of a term's block.
    pub fn from_index(index: u32) -> Option<Slot> {
        Slot::ALL.get(index as usize).copied()
    }
}

/// The variable name of a term's parameter: `discovered{term}_{suffix}`, `term` 1-based.
pub fn variable_name(term: usize, slot: Slot) -> String {
    format!("discovered{term}_{}", slot.suffix())
}

/// A candidate function of a site's `(x, v)`. The codes (`discovered{i}_function`) and names are
/// stable: reports and parameter files use them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Function {
    /// `x`
    X,
    /// `x^2`
    X2,
    /// `x^3`
    X3,
    /// `x|x|`
    XAbsX,
    /// `v`
    V,
    /// `v^2`
    V2,
    /// `v|v|`
    VAbsV,
    /// `v^3`
    V3,
    /// `sign(v)` (0 at v = 0)
    SignV,
    /// `tanh(v/s)`
    TanhV,
    /// `max(0,x-s)`: a one-sided ramp beyond `+s` (a bumper on the positive side)
    RampUp,
    /// `min(0,x+s)`: a one-sided ramp beyond `−s` (a bumper on the negative side)
    RampDown,
    /// `x^2*v`: nonlinear damping growing with the displacement
    X2V,
}

impl Function {
    /// Every function, in code order (code = index + 1).
    pub const ALL: [Function; 13] = [
        Function::X,
        Function::X2,
        Function::X3,
        Function::XAbsX,
        Function::V,
        Function::V2,
        Function::VAbsV,
        Function::V3,
        Function::SignV,
        Function::TanhV,
        Function::RampUp,
        Function::RampDown,
        Function::X2V,
    ];
    /// The largest code.
    pub const LAST_CODE: i32 = Function::ALL.len() as i32;

    /// The stable integer code, 1..=[`Function::LAST_CODE`].
    pub fn code(self) -> i32 {
        Function::ALL
            .iter()
            .position(|&f| f == self)
            .map_or(0, |i| i as i32 + 1)
    }

    pub fn from_code(code: i32) -> Option<Function> {
        usize::try_from(code - 1)
            .ok()
            .and_then(|i| Function::ALL.get(i).copied())
    }

    /// The name used in reports: `x`, `x^2`, `x^3`, `x|x|`, `v`, `v^2`, `v|v|`, `v^3`,
    /// `sign(v)`, `tanh(v/s)`, `max(0,x-s)`, `min(0,x+s)`, `x^2*v`.
    pub fn name(self) -> &'static str {
        match self {
            Function::X => "x",
            Function::X2 => "x^2",
            Function::X3 => "x^3",
            Function::XAbsX => "x|x|",
            Function::V => "v",
            Function::V2 => "v^2",
            Function::VAbsV => "v|v|",
            Function::V3 => "v^3",
            Function::SignV => "sign(v)",
            Function::TanhV => "tanh(v/s)",
            Function::RampUp => "max(0,x-s)",
            Function::RampDown => "min(0,x+s)",
            Function::X2V => "x^2*v",
        }
    }

    /// The function named `text` (its [`Function::name`], spaces ignored) or its code.
    pub fn parse(text: &str) -> Option<Function> {
        let compact: String = text.chars().filter(|c| !c.is_whitespace()).collect();
        Function::ALL
            .iter()
            .copied()
            .find(|f| f.name() == compact)
            .or_else(|| compact.parse().ok().and_then(Function::from_code))
    }

    /// Does the value depend on the term's `scale`?
    pub fn uses_scale(self) -> bool {
        matches!(
            self,
            Function::TanhV | Function::RampUp | Function::RampDown
        )
    }

    /// The function's value at `(x, v)`; `scale` (> 0) matters only where
    /// [`Function::uses_scale`].
    #[inline]
    pub fn eval(self, x: f64, v: f64, scale: f64) -> f64 {
        match self {
            Function::X => x,
            Function::X2 => x * x,
            Function::X3 => x * x * x,
            Function::XAbsX => x * x.abs(),
            Function::V => v,
            Function::V2 => v * v,
            Function::VAbsV => v * v.abs(),
            Function::V3 => v * v * v,
            Function::SignV => {
                if v > 0.0 {
                    1.0
                } else if v < 0.0 {
                    -1.0
                } else {
                    0.0
                }
            }
            Function::TanhV => (v / scale).tanh(),
            Function::RampUp => (x - scale).max(0.0),
            Function::RampDown => (x + scale).min(0.0),
            Function::X2V => x * x * v,
        }
    }

    /// The switch function whose sign change is the kink of a ramp (`x − s`, `x + s`), none for
    /// the others.
    #[inline]
    pub fn switch(self, x: f64, scale: f64) -> Option<f64> {
        match self {
            Function::RampUp => Some(x - scale),
            Function::RampDown => Some(x + scale),
            _ => None,
        }
    }
}

impl fmt::Display for Function {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Where a term acts: a storey (its drift and drift rate) or a floor (its displacement and
/// velocity), 1-based 1..=N.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Site {
    Storey(usize),
    Floor(usize),
}

/// `discovered{i}_placement` of a storey site.
pub const PLACEMENT_STOREY: i32 = 0;
/// `discovered{i}_placement` of a floor site.
pub const PLACEMENT_FLOOR: i32 = 1;

impl Site {
    /// Every site of a building of `storeys` storeys: storeys 1..N, then floors 1..N.
    pub fn all(storeys: usize) -> Vec<Site> {
        (1..=storeys)
            .map(Site::Storey)
            .chain((1..=storeys).map(Site::Floor))
            .collect()
    }

    /// The 1-based storey or floor number.
    pub fn at(self) -> usize {
        match self {
            Site::Storey(n) | Site::Floor(n) => n,
        }
    }

    /// `discovered{i}_placement`: 0 storey, 1 floor.
    pub fn placement_code(self) -> i32 {
        match self {
            Site::Storey(_) => PLACEMENT_STOREY,
            Site::Floor(_) => PLACEMENT_FLOOR,
        }
    }

    /// The site of a placement code and a 1-based number, if both are valid in a building of
    /// `storeys` storeys.
    pub fn from_codes(placement: i32, at: i32, storeys: usize) -> Option<Site> {
        let n = usize::try_from(at)
            .ok()
            .filter(|n| (1..=storeys).contains(n))?;
        match placement {
            PLACEMENT_STOREY => Some(Site::Storey(n)),
            PLACEMENT_FLOOR => Some(Site::Floor(n)),
            _ => None,
        }
    }

    /// Is the number in 1..=`storeys`?
    pub fn is_valid(self, storeys: usize) -> bool {
        (1..=storeys).contains(&self.at())
    }

    /// "storey 2", "floor 1" (also "storey2", case-insensitive), in a building of `storeys`
    /// storeys: the location of the text form (`discovered@storey2`).
    pub fn parse(text: &str, storeys: usize) -> Option<Site> {
        Site::at_location(Location::parse(text).ok()?, storeys)
    }

    /// The site a location names (`storeyN` or `floorN`), if the building has it.
    pub fn at_location(location: Location, storeys: usize) -> Option<Site> {
        let (placement, n) = match location {
            Location::Storey(n) => (PLACEMENT_STOREY, n),
            Location::Floor(n) => (PLACEMENT_FLOOR, n),
            Location::Number(_) | Location::Between(..) => return None,
        };
        Site::from_codes(placement, i32::try_from(n).ok()?, storeys)
    }

    /// The site as the text form writes it: `storey2`, `floor1`.
    pub fn location(self) -> Location {
        match self {
            Site::Storey(n) => Location::Storey(n),
            Site::Floor(n) => Location::Floor(n),
        }
    }

    /// The site's `(x, v)`: drift and drift rate of a storey, displacement and velocity of a
    /// floor. The site must be valid.
    #[inline]
    pub fn state(self, y: &[f64], v: &[f64]) -> (f64, f64) {
        (self.of(y), self.of(v))
    }

    /// The site's share of floor values: a storey's drift, a floor's own value.
    #[inline]
    fn of(self, floors: &[f64]) -> f64 {
        match self {
            Site::Storey(n) => drift(floors, n - 1),
            Site::Floor(n) => floors[n - 1],
        }
    }

    /// Add a site force `f` to `g`: a storey force on both floors of the storey, a floor force on
    /// the floor.
    #[inline]
    pub fn add_force(self, f: f64, g: &mut [f64]) {
        match self {
            Site::Storey(n) => add_storey_force(n - 1, f, g),
            Site::Floor(n) => g[n - 1] += f,
        }
    }
}

impl fmt::Display for Site {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Site::Storey(n) => write!(f, "storey {n}"),
            Site::Floor(n) => write!(f, "floor {n}"),
        }
    }
}

/// One discovered term: `coefficient · function(x, v; scale)` at `site`. The coefficient is in
/// N per unit of the function (N·m⁻³ for `x^3`, N·s/m for `v`, N for `sign(v)`), the scale in m
/// for the ramps and m/s for `tanh(v/s)`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Term {
    pub function: Function,
    pub site: Site,
    pub coefficient: f64,
    pub scale: f64,
}

/// The scale a term starts with (and the FMU's start value): 1 mm or 1 mm/s.
pub const DEFAULT_SCALE: f64 = 1e-3;

impl Term {
    /// A term with the default scale.
    pub fn new(function: Function, site: Site, coefficient: f64) -> Term {
        Term {
            function,
            site,
            coefficient,
            scale: DEFAULT_SCALE,
        }
    }

    /// The term's force for the site's `(x, v)` (positive resists a positive `x` at a storey,
    /// pushes back a floor at a floor).
    #[inline]
    pub fn force_at(&self, x: f64, v: f64) -> f64 {
        self.coefficient * self.function.eval(x, v, self.scale)
    }

    /// Add the term's force at the floors' state `(y, v)` to `g`.
    #[inline]
    pub fn add_force(&self, y: &[f64], v: &[f64], g: &mut [f64]) {
        let (x, xv) = self.site.state(y, v);
        self.site.add_force(self.force_at(x, xv), g);
    }

    /// The ramp's switch function at the floors' displacements, if the function is a ramp.
    #[inline]
    pub fn switch(&self, y: &[f64]) -> Option<f64> {
        self.function.switch(self.site.of(y), self.scale)
    }

    /// Check the term as term `index` (1-based, for the variable names in the error) of a
    /// building of `storeys` storeys.
    pub fn validate(&self, index: usize, storeys: usize) -> Result<(), InvalidParameter> {
        if !self.site.is_valid(storeys) {
            return Err(invalid(
                index,
                Slot::At,
                format!("{} is outside [1, {storeys}]", self.site.at()),
            ));
        }
        check_coefficient(index, self.coefficient)?;
        check_scale(index, self.scale)
    }

    /// The term's parameters as term `index` (1-based) sets them through FMI:
    /// `discovered{index}_function`, `_placement`, `_at` (Integers) …
    pub fn integer_parameters(&self, index: usize) -> [(String, i32); 3] {
        [
            (variable_name(index, Slot::Function), self.function.code()),
            (
                variable_name(index, Slot::Placement),
                self.site.placement_code(),
            ),
            (variable_name(index, Slot::At), self.site.at() as i32),
        ]
    }

    /// … and `discovered{index}_coefficient`, `_scale` (Reals); `_enabled` is true.
    pub fn real_parameters(&self, index: usize) -> [(String, f64); 2] {
        [
            (variable_name(index, Slot::Coefficient), self.coefficient),
            (variable_name(index, Slot::Scale), self.scale),
        ]
    }
}

impl fmt::Display for Term {
    /// `1.5e9·x^3 at storey 3`, with `(s = …)` for the functions that use it.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:e}·{} at {}",
            self.coefficient, self.function, self.site
        )?;
        if self.function.uses_scale() {
            write!(f, " (s = {:e})", self.scale)?;
        }
        Ok(())
    }
}

/// The error for term `index`'s parameter `slot`.
pub fn invalid(index: usize, slot: Slot, reason: String) -> InvalidParameter {
    InvalidParameter {
        name: variable_name(index, slot),
        reason,
    }
}

/// A coefficient is finite.
pub fn check_coefficient(index: usize, value: f64) -> Result<(), InvalidParameter> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(invalid(
            index,
            Slot::Coefficient,
            format!("{value} must be finite"),
        ))
    }
}

/// A scale is finite and > 0.
pub fn check_scale(index: usize, value: f64) -> Result<(), InvalidParameter> {
    if value > 0.0 && value.is_finite() {
        Ok(())
    } else {
        Err(invalid(
            index,
            Slot::Scale,
            format!("{value} must be > 0 and finite"),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::paper::STOREYS as PAPER_STOREYS;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * (1.0 + a.abs().max(b.abs()))
    }

    #[test]
    fn each_function_has_its_value() {
        let s = 1e-3;
        // (function, x, v, expected)
        let cases: &[(Function, f64, f64, f64)] = &[
            (Function::X, 2.0, 7.0, 2.0),
            (Function::X, -3.0, 7.0, -3.0),
            (Function::X2, -3.0, 7.0, 9.0),
            (Function::X3, -2.0, 7.0, -8.0),
            (Function::XAbsX, -3.0, 7.0, -9.0),
            (Function::XAbsX, 3.0, 7.0, 9.0),
            (Function::V, 7.0, -0.5, -0.5),
            (Function::V2, 7.0, -0.5, 0.25),
            (Function::VAbsV, 7.0, -0.5, -0.25),
            (Function::VAbsV, 7.0, 0.5, 0.25),
            (Function::V3, 7.0, -0.5, -0.125),
            (Function::SignV, 7.0, -0.5, -1.0),
            (Function::SignV, 7.0, 1e-12, 1.0),
            (Function::SignV, 7.0, 0.0, 0.0),
            (Function::TanhV, 7.0, 1e-3, 1f64.tanh()),
            (Function::TanhV, 7.0, -2e-3, -(2f64.tanh())),
            (Function::TanhV, 7.0, 0.0, 0.0),
            (Function::RampUp, 0.5e-3, 9.0, 0.0),
            (Function::RampUp, -5e-3, 9.0, 0.0),
            (Function::RampUp, 3e-3, 9.0, 2e-3),
            (Function::RampDown, -0.5e-3, 9.0, 0.0),
            (Function::RampDown, 5e-3, 9.0, 0.0),
            (Function::RampDown, -3e-3, 9.0, -2e-3),
            (Function::X2V, -2.0, 0.5, 2.0),
            (Function::X2V, 3.0, -1.0, -9.0),
        ];
        for &(f, x, v, expected) in cases {
            let got = f.eval(x, v, s);
            assert!(
                close(got, expected),
                "{f}({x}, {v}) = {got}, expected {expected}"
            );
        }
        // Only tanh and the ramps read the scale.
        for f in Function::ALL {
            let differs = [2e-3, -2e-3]
                .into_iter()
                .any(|x| f.eval(x, 3e-3, 1e-3) != f.eval(x, 3e-3, 5e-4));
            assert_eq!(differs, f.uses_scale(), "{f}");
        }
    }

    #[test]
    fn codes_and_names_parse_back() {
        assert_eq!(Function::ALL.len(), 13);
        assert_eq!(Function::LAST_CODE, 13);
        for (i, f) in Function::ALL.into_iter().enumerate() {
            assert_eq!(f.code(), i as i32 + 1);
            assert_eq!(Function::from_code(f.code()), Some(f));
            assert_eq!(Function::parse(f.name()), Some(f));
            assert_eq!(Function::parse(&f.code().to_string()), Some(f));
        }
        assert_eq!(Function::parse(" max(0, x - s) "), Some(Function::RampUp));
        assert_eq!(Function::from_code(0), None);
        assert_eq!(Function::from_code(14), None);
        assert_eq!(Function::parse("x^4"), None);
        for site in Site::all(PAPER_STOREYS) {
            assert_eq!(Site::parse(&site.to_string(), PAPER_STOREYS), Some(site));
            assert_eq!(
                Site::from_codes(site.placement_code(), site.at() as i32, PAPER_STOREYS),
                Some(site)
            );
        }
        assert_eq!(
            Site::parse("storey 2", PAPER_STOREYS),
            Some(Site::Storey(2))
        );
        assert_eq!(Site::parse("Floor1", PAPER_STOREYS), Some(Site::Floor(1)));
        assert_eq!(Site::parse("floor 4", PAPER_STOREYS), None);
        assert_eq!(Site::parse("storey 0", PAPER_STOREYS), None);
        assert_eq!(Site::parse("roof 1", PAPER_STOREYS), None);
        assert_eq!(Site::Storey(2).to_string(), "storey 2");
        assert_eq!(Site::Floor(1).to_string(), "floor 1");
    }

    #[test]
    fn a_storey_term_is_a_storey_force_and_a_floor_term_acts_on_its_floor() {
        let y = [1e-3, 3e-3, 2e-3];
        let v = [0.01, -0.02, 0.05];
        for storey in 1..=3 {
            let term = Term::new(Function::X, Site::Storey(storey), 5000.0);
            let mut g = [0.0; 3];
            term.add_force(&y, &v, &mut g);
            let mut expected = [0.0; 3];
            add_storey_force(storey - 1, 5000.0 * drift(&y, storey - 1), &mut expected);
            assert_eq!(g, expected, "storey {storey}");
        }
        // Storey 2's drift is +2 mm: a positive x-coefficient pushes floor 2 (upper) back and
        // floor 1 (lower) forward.
        let mut g = [0.0; 3];
        Term::new(Function::X, Site::Storey(2), 1000.0).add_force(&y, &v, &mut g);
        assert!(
            close(g[1], 2.0) && close(g[0], -2.0) && g[2] == 0.0,
            "{g:?}"
        );
        // The storey's v is its drift rate: storey 3's is 0.05 − (−0.02).
        let mut g = [0.0; 3];
        Term::new(Function::V, Site::Storey(3), 10.0).add_force(&y, &v, &mut g);
        assert!(
            close(g[2], 0.7) && close(g[1], -0.7) && g[0] == 0.0,
            "{g:?}"
        );
        // A floor term acts on its floor only, against its displacement or velocity.
        for floor in 1..=3 {
            let mut g = [0.0; 3];
            Term::new(Function::V, Site::Floor(floor), 2.0).add_force(&y, &v, &mut g);
            for (i, gi) in g.iter().enumerate() {
                let expected = if i == floor - 1 { 2.0 * v[i] } else { 0.0 };
                assert_eq!(*gi, expected, "floor {floor}: {g:?}");
            }
        }
        // Storey 1's drift is floor 1's displacement (the ground does not move).
        let (x, xv) = Site::Storey(1).state(&y, &v);
        assert_eq!((x, xv), (y[0], v[0]));
    }

    #[test]
    fn ramps_switch_at_their_kinks() {
        let y = [0.0, 1.5e-3, 1.0e-3];
        let up = Term {
            scale: 1e-3,
            ..Term::new(Function::RampUp, Site::Storey(2), 1.0)
        };
        let down = Term {
            function: Function::RampDown,
            ..up
        };
        assert!(close(up.switch(&y).expect("a ramp switches"), 0.5e-3));
        assert!(close(down.switch(&y).expect("a ramp switches"), 2.5e-3));
        assert_eq!(
            Term::new(Function::X3, Site::Storey(2), 1.0).switch(&y),
            None
        );
    }
}
