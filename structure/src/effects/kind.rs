//! The kinds as data, for every crate (the shear FMU, the diagnosis, the synthetic structure):
//! which kinds there are, where each sits, its parameters with their defaults, and its force law
//! as a function. It reads the kinds' own files, so it cannot drift from them.

use serde::{Deserialize, Serialize};

use super::contact::{SIDE_BOTH, SIDE_NEGATIVE, SIDE_POSITIVE};
use super::label::{one_of, LabelError, Location};
use super::{Contact, Cubic, Effect, Friction, RealParam};

/// The kinds of effect the library has.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    Contact,
    Cubic,
    Friction,
}

/// Where a kind sits, and what its force is a function of.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Placement {
    /// In a storey (0 = ground–floor 1): a force of the storey drift, pushing its two floors
    /// apart (see [`super::add_storey_force`]).
    Storey,
    /// On a floor: a force of the floor's velocity, on that floor.
    Floor,
}

/// Which drift closes a contact gap (the FMU's `contactXY_side`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    Both,
    Positive,
    Negative,
}

impl Side {
    pub const ALL: [Side; 3] = [Side::Both, Side::Positive, Side::Negative];

    pub fn name(self) -> &'static str {
        match self {
            Side::Both => "both",
            Side::Positive => "positive",
            Side::Negative => "negative",
        }
    }

    /// The FMU's integer: 0 both, 1 positive, −1 negative.
    pub fn code(self) -> i32 {
        match self {
            Side::Both => SIDE_BOTH,
            Side::Positive => SIDE_POSITIVE,
            Side::Negative => SIDE_NEGATIVE,
        }
    }

    pub fn from_code(code: i32) -> Option<Side> {
        Side::ALL.into_iter().find(|s| s.code() == code)
    }

    /// A name or the FMU's integer written out: `both`/`0`, `positive`/`1`, `negative`/`-1`.
    pub fn parse(text: &str) -> Option<Side> {
        match text {
            "both" | "0" => Some(Side::Both),
            "positive" | "1" => Some(Side::Positive),
            "negative" | "-1" => Some(Side::Negative),
            _ => None,
        }
    }
}

impl Kind {
    pub const ALL: [Kind; 3] = [Kind::Contact, Kind::Cubic, Kind::Friction];

    /// "contact", "cubic", "friction".
    pub fn name(self) -> &'static str {
        match self {
            Kind::Contact => Contact::KIND,
            Kind::Cubic => Cubic::KIND,
            Kind::Friction => Friction::KIND,
        }
    }

    pub fn parse(name: &str) -> Option<Kind> {
        Kind::ALL.into_iter().find(|k| k.name() == name)
    }

    pub fn placement(self) -> Placement {
        match self {
            Kind::Contact | Kind::Cubic => Placement::Storey,
            Kind::Friction => Placement::Floor,
        }
    }

    /// How many sites the kind has in a building of `storeys` storeys (its storeys or its
    /// floors).
    pub fn sites(self, storeys: usize) -> usize {
        match self {
            Kind::Contact => Contact::sites(storeys),
            Kind::Cubic => Cubic::sites(storeys),
            Kind::Friction => Friction::sites(storeys),
        }
    }

    /// The site (0-based) that `location` names for this kind in a building of `storeys`
    /// storeys: for contact two adjacent floors `L-U` (0 the ground) or `storeyN`; for cubic a
    /// storey, `N`, `storeyN` or two adjacent floors; for friction a floor, `N` or `floorN`.
    pub fn site(self, location: Location, storeys: usize) -> Result<usize, LabelError> {
        match self {
            Kind::Contact => match location {
                Location::Between(lower, upper) if upper == lower + 1 && upper <= storeys => {
                    Ok(lower)
                }
                Location::Storey(s) if (1..=storeys).contains(&s) => Ok(s - 1),
                _ => Err(LabelError(format!(
                    "contact acts between adjacent floors {}",
                    one_of((1..=storeys).map(|upper| format!("{}-{upper}", upper - 1)))
                ))),
            },
            Kind::Cubic => location
                .storey(storeys)
                .map(|s| s - 1)
                .ok_or_else(|| LabelError(format!("cubic is at storey {}", one_of(1..=storeys)))),
            Kind::Friction => location
                .floor(storeys)
                .map(|f| f - 1)
                .ok_or_else(|| LabelError(format!("friction is at floor {}", one_of(1..=storeys)))),
        }
    }

    /// Site `location` (0-based) as the text form writes it: `2-3` (contact), `2` (cubic's
    /// storey, friction's floor).
    pub fn location(self, location: usize) -> Location {
        match self {
            Kind::Contact => Location::Between(location, location + 1),
            Kind::Cubic | Kind::Friction => Location::Number(location + 1),
        }
    }

    /// Whether the kind has a side (only contact).
    pub fn has_side(self) -> bool {
        self == Kind::Contact
    }

    /// The real parameters, in the order [`Law::new`] takes them, with their start values.
    pub fn real_params(self) -> &'static [RealParam] {
        match self {
            Kind::Contact => Contact::real_params(),
            Kind::Cubic => Cubic::real_params(),
            Kind::Friction => Friction::real_params(),
        }
    }

    /// The FMU variables' prefix at `location` (0-based), e.g. "contact23", "cubic2".
    pub fn prefix(self, location: usize) -> String {
        match self {
            Kind::Contact => Contact::prefix(location),
            Kind::Cubic => Cubic::prefix(location),
            Kind::Friction => Friction::prefix(location),
        }
    }

    /// The location in words: "between floors 2 and 3", "of storey 2", "on floor 1".
    pub fn where_(self, location: usize) -> String {
        match self {
            Kind::Contact => Contact::where_(location),
            Kind::Cubic => Cubic::where_(location),
            Kind::Friction => Friction::where_(location),
        }
    }
}

/// One effect with its parameter values: the force law of its kind.
#[derive(Clone, Debug, PartialEq)]
pub enum Law {
    Contact(Contact),
    Cubic(Cubic),
    Friction(Friction),
}

impl Law {
    /// The law of `kind` with the real parameters `reals` (in [`Kind::real_params`]'s order) and,
    /// for contact, `side`. `None` when `reals` is shorter than the kind's parameter list.
    pub fn new(kind: Kind, reals: &[f64], side: Side) -> Option<Law> {
        let mut law = Law::at_start(kind);
        if reals.len() < kind.real_params().len() {
            return None;
        }
        for (i, &x) in reals.iter().take(kind.real_params().len()).enumerate() {
            law.set_real(i, x);
        }
        if let Law::Contact(c) = &mut law {
            c.side = side.code();
        }
        Some(law)
    }

    /// Every parameter at its start value (contact: both sides).
    pub fn at_start(kind: Kind) -> Law {
        match kind {
            Kind::Contact => Law::Contact(Contact::at_start(0)),
            Kind::Cubic => Law::Cubic(Cubic::at_start(0)),
            Kind::Friction => Law::Friction(Friction::at_start(0)),
        }
    }

    pub fn kind(&self) -> Kind {
        match self {
            Law::Contact(_) => Kind::Contact,
            Law::Cubic(_) => Kind::Cubic,
            Law::Friction(_) => Kind::Friction,
        }
    }

    fn set_real(&mut self, index: usize, value: f64) {
        match self {
            Law::Contact(e) => e.set_real(index, value),
            Law::Cubic(e) => e.set_real(index, value),
            Law::Friction(e) => e.set_real(index, value),
        }
    }

    /// The real parameters, in [`Kind::real_params`]'s order.
    pub fn reals(&self) -> Vec<f64> {
        let n = self.kind().real_params().len();
        (0..n)
            .map(|i| match self {
                Law::Contact(e) => e.real(i),
                Law::Cubic(e) => e.real(i),
                Law::Friction(e) => e.real(i),
            })
            .collect()
    }

    /// The force of the law: of the storey drift (contact, cubic; positive resists a positive
    /// drift) or of the floor velocity (friction; positive resists a positive velocity).
    #[inline]
    pub fn force_at(&self, x: f64) -> f64 {
        match self {
            Law::Contact(e) => e.force_at(x),
            Law::Cubic(e) => e.force_at(x),
            Law::Friction(e) => e.force_at(x),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_sides_read_back() {
        for kind in Kind::ALL {
            assert_eq!(Kind::parse(kind.name()), Some(kind));
        }
        for side in Side::ALL {
            assert_eq!(Side::parse(side.name()), Some(side));
            assert_eq!(Side::from_code(side.code()), Some(side));
        }
        assert_eq!(Kind::Contact.prefix(2), "contact23");
        assert_eq!(Kind::Contact.prefix(8), "contact89");
        assert_eq!(Kind::Contact.prefix(9), "contact9to10");
        assert_eq!(Kind::Contact.prefix(10), "contact10to11");
        assert_eq!(Kind::Cubic.prefix(11), "cubic12");
        assert_eq!(Kind::Friction.prefix(19), "friction20");
        // Every site's prefix of a building of MAX_STOREYS storeys is its own, and no prefix
        // followed by `_` starts another (`cubic1_` is not the start of `cubic12_`).
        let n = crate::MAX_STOREYS;
        let prefixes: Vec<String> = Kind::ALL
            .into_iter()
            .flat_map(|kind| (0..kind.sites(n)).map(move |s| kind.prefix(s) + "_"))
            .collect();
        for (i, a) in prefixes.iter().enumerate() {
            for (j, b) in prefixes.iter().enumerate() {
                assert!(i == j || !b.starts_with(a.as_str()), "{a} starts {b}");
            }
        }
        assert!(Law::new(Kind::Friction, &[0.1], Side::Both).is_none());
    }

    /// Every site reads back from its text form, for buildings of 1, 3 and 12 storeys; what a
    /// kind cannot sit at is refused saying where it can.
    #[test]
    fn sites_read_back_from_their_text_and_the_rest_is_refused() {
        for storeys in [1, 3, 12, crate::MAX_STOREYS] {
            for kind in Kind::ALL {
                assert_eq!(kind.sites(storeys), storeys);
                for site in 0..kind.sites(storeys) {
                    let location =
                        Location::parse(&kind.location(site).to_string()).expect("the text form");
                    assert_eq!(kind.site(location, storeys), Ok(site), "{kind:?} {site}");
                }
                assert!(kind.site(kind.location(storeys), storeys).is_err());
            }
        }
        assert_eq!(Kind::Contact.site(Location::Storey(3), 3), Ok(2));
        assert_eq!(Kind::Cubic.site(Location::Between(1, 2), 3), Ok(1));
        let says = |kind: Kind, location| kind.site(location, 3).expect_err("refused").to_string();
        assert_eq!(
            says(Kind::Contact, Location::Between(1, 3)),
            "contact acts between adjacent floors 0-1, 1-2 or 2-3"
        );
        assert_eq!(
            says(Kind::Contact, Location::Number(2)),
            says(Kind::Contact, Location::Between(3, 4))
        );
        assert_eq!(
            says(Kind::Cubic, Location::Number(4)),
            "cubic is at storey 1, 2 or 3"
        );
        assert_eq!(
            says(Kind::Cubic, Location::Floor(2)),
            "cubic is at storey 1, 2 or 3"
        );
        assert_eq!(
            says(Kind::Friction, Location::Storey(2)),
            "friction is at floor 1, 2 or 3"
        );
        assert_eq!(
            says(Kind::Friction, Location::Number(0)),
            "friction is at floor 1, 2 or 3"
        );
    }
}
