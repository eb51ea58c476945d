//! The one text form of an effect: `KIND@LOC[:k=v,...]`, as `twin synth --effect`,
//! `twin diagnose --effects`, `twin add-physics --effect` and the diagnosis report's labels
//! write it.
//!
//! - `KIND`: a kind of the catalogue (`contact`, `cubic`, `friction`), `discovered`, or a kind
//!   a caller adds (the synthetic structure's `hysteresis` and `quadratic-damping`);
//! - `LOC`: `N` (a storey or a floor, as the kind sits), `L-U` (two floors, 0 the ground: the
//!   storey between them when they are adjacent), `storeyN` or `floorN` (case and spaces
//!   ignored: `storey 2`, `Floor1`);
//! - `k=v`: parameters by name, separated by commas; a side alone (`contact@2-3:positive`) is
//!   short for `side=positive`.
//!
//! [`Label::parse`] reads the form, [`Label`]'s `Display` writes it back (a side alone);
//! what a location means for a kind is [`super::Kind::site`].

use std::fmt;

use super::Side;

/// Where an effect's text puts it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Location {
    /// `2`: a storey or a floor, as the kind sits.
    Number(usize),
    /// `2-3`: between two floors, 0 the ground.
    Between(usize, usize),
    /// `storey2`.
    Storey(usize),
    /// `floor1`.
    Floor(usize),
}

/// An effect's text read: its kind as written, where, and its parameters in order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Label {
    pub kind: String,
    pub location: Location,
    /// `(key, value)` as written; a side alone is `("side", side)`.
    pub params: Vec<(String, String)>,
}

/// Why a text is not `KIND@LOC[:k=v,...]`. Callers put the text and where it came from in front.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct LabelError(pub String);

/// What `LOC` may be, for the messages.
const LOCATION_FORMS: &str = "N, L-U (floors, 0 the ground), storeyN or floorN";

impl Label {
    /// A label with no parameters.
    pub fn new(kind: &str, location: Location) -> Label {
        Label {
            kind: kind.to_string(),
            location,
            params: Vec::new(),
        }
    }

    /// Read `KIND@LOC[:k=v,...]`.
    pub fn parse(text: &str) -> Result<Label, LabelError> {
        let (head, params) = match text.split_once(':') {
            Some((head, params)) => (head, Some(params)),
            None => (text, None),
        };
        let (kind, location) = head.split_once('@').ok_or_else(|| {
            LabelError("expected KIND@LOCATION[:KEY=VALUE,...], e.g. contact@2-3 or cubic@2".into())
        })?;
        let kind = kind.trim();
        if kind.is_empty() {
            return Err(LabelError(
                "the kind is missing; expected KIND@LOCATION".into(),
            ));
        }
        let location = Location::parse(location)?;
        let mut pairs = Vec::new();
        for param in params
            .into_iter()
            .flat_map(|p| p.split(','))
            .map(str::trim)
            .filter(|p| !p.is_empty())
        {
            match param.split_once('=') {
                Some((key, value)) => {
                    pairs.push((key.trim().to_string(), value.trim().to_string()));
                }
                None if Side::parse(param).is_some() => {
                    pairs.push(("side".to_string(), param.to_string()));
                }
                None => {
                    return Err(LabelError(format!(
                        "side '{param}' is not both, positive or negative (other parameters are KEY=VALUE)"
                    )))
                }
            }
        }
        Ok(Label {
            kind: kind.to_string(),
            location,
            params: pairs,
        })
    }

    /// The value of parameter `key`, the last one given.
    pub fn param(&self, key: &str) -> Option<&str> {
        self.params
            .iter()
            .rev()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

impl fmt::Display for Label {
    /// `contact@2-3:positive`, `friction@1:force=0.2,velocity_scale=0.001`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}@{}", self.kind, self.location)?;
        for (i, (key, value)) in self.params.iter().enumerate() {
            f.write_str(if i == 0 { ":" } else { "," })?;
            if key == "side" {
                f.write_str(value)?;
            } else {
                write!(f, "{key}={value}")?;
            }
        }
        Ok(())
    }
}

impl Location {
    /// `N`, `L-U`, `storeyN` or `floorN` (case and spaces ignored).
    pub fn parse(text: &str) -> Result<Location, LabelError> {
        let compact: String = text
            .chars()
            .filter(|c| !c.is_whitespace())
            .collect::<String>()
            .to_ascii_lowercase();
        let bad = || {
            LabelError(format!(
                "'{}' is not a floor number; the location is {LOCATION_FORMS}",
                text.trim()
            ))
        };
        let number = |s: &str| s.parse::<usize>().map_err(|_| bad());
        if let Some(rest) = compact.strip_prefix("storey") {
            return Ok(Location::Storey(number(rest)?));
        }
        if let Some(rest) = compact.strip_prefix("floor") {
            return Ok(Location::Floor(number(rest)?));
        }
        match compact.split_once('-') {
            Some((lower, upper)) => {
                let lower = lower.parse::<usize>().map_err(|_| {
                    LabelError(format!(
                        "'{lower}' is not a floor number; the location is {LOCATION_FORMS}"
                    ))
                })?;
                let upper = upper.parse::<usize>().map_err(|_| {
                    LabelError(format!(
                        "'{upper}' is not a floor number; the location is {LOCATION_FORMS}"
                    ))
                })?;
                Ok(Location::Between(lower, upper))
            }
            None => Ok(Location::Number(number(&compact)?)),
        }
    }

    /// The location given as a list of floor numbers (the scenario file's `location`): one
    /// number, or two.
    pub fn from_numbers(numbers: &[usize]) -> Option<Location> {
        match *numbers {
            [n] => Some(Location::Number(n)),
            [lower, upper] => Some(Location::Between(lower, upper)),
            _ => None,
        }
    }

    /// The storey (1-based) it names in a building of `storeys` storeys: `N` or `storeyN`, or
    /// two adjacent floors `L-U` (storey U).
    pub fn storey(self, storeys: usize) -> Option<usize> {
        let s = match self {
            Location::Number(s) | Location::Storey(s) => s,
            Location::Between(lower, upper) if upper == lower + 1 => upper,
            _ => return None,
        };
        (1..=storeys).contains(&s).then_some(s)
    }

    /// The floor (1-based) it names in a building of `storeys` storeys: `N` or `floorN`.
    pub fn floor(self, storeys: usize) -> Option<usize> {
        match self {
            Location::Number(f) | Location::Floor(f) if (1..=storeys).contains(&f) => Some(f),
            _ => None,
        }
    }
}

impl fmt::Display for Location {
    /// `2`, `2-3`, `storey2`, `floor1`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Number(n) => write!(f, "{n}"),
            Location::Between(lower, upper) => write!(f, "{lower}-{upper}"),
            Location::Storey(n) => write!(f, "storey{n}"),
            Location::Floor(n) => write!(f, "floor{n}"),
        }
    }
}

/// `1, 2 or 3`: the items in words.
pub fn one_of<T: fmt::Display>(items: impl IntoIterator<Item = T>) -> String {
    let items: Vec<String> = items.into_iter().map(|x| x.to_string()).collect();
    match items.split_last() {
        None => String::new(),
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_form_reads_and_writes_back() {
        for (text, kind, location, params) in [
            ("contact@2-3", "contact", Location::Between(2, 3), vec![]),
            ("cubic@2", "cubic", Location::Number(2), vec![]),
            ("friction@floor1", "friction", Location::Floor(1), vec![]),
            (
                "discovered@storey2",
                "discovered",
                Location::Storey(2),
                vec![],
            ),
            (
                "contact@2-3:positive",
                "contact",
                Location::Between(2, 3),
                vec![("side", "positive")],
            ),
            (
                "friction@1:force=0.2,velocity_scale=0.001",
                "friction",
                Location::Number(1),
                vec![("force", "0.2"), ("velocity_scale", "0.001")],
            ),
        ] {
            let label = Label::parse(text).expect(text);
            let expected = Label {
                kind: kind.into(),
                location,
                params: params
                    .iter()
                    .map(|(k, v)| (k.to_string(), v.to_string()))
                    .collect(),
            };
            assert_eq!(label, expected, "{text}");
            assert_eq!(label.to_string(), text);
        }
        // A side given as KEY=VALUE, spaces and case in the location: the same label.
        let long = Label::parse("contact@ 2 - 3 :side=negative, gap = 5e-4").expect("long form");
        assert_eq!(long.to_string(), "contact@2-3:negative,gap=5e-4");
        assert_eq!(long.param("gap"), Some("5e-4"));
        assert_eq!(
            Label::parse("discovered@Storey 2").map(|l| l.location),
            Ok(Location::Storey(2))
        );
    }

    #[test]
    fn a_text_outside_the_grammar_is_refused_with_the_reason() {
        for (text, says) in [
            ("contact2-3", "KIND@LOCATION"),
            ("cubic", "expected"),
            ("@2", "kind is missing"),
            ("friction@x", "'x' is not a floor number"),
            ("quadratic-damping@floorx", "floorN"),
            ("contact@a-3", "'a' is not a floor number"),
            ("contact@2-3:up", "side 'up'"),
        ] {
            let e = Label::parse(text).expect_err(text).to_string();
            assert!(e.contains(says), "{text}: {e}");
        }
    }

    #[test]
    fn locations_name_storeys_and_floors_of_the_building() {
        assert_eq!(Location::Number(2).storey(3), Some(2));
        assert_eq!(Location::Between(1, 2).storey(3), Some(2));
        assert_eq!(Location::Storey(3).storey(3), Some(3));
        assert_eq!(Location::Between(1, 3).storey(3), None);
        assert_eq!(Location::Number(4).storey(3), None);
        assert_eq!(Location::Number(4).storey(5), Some(4));
        assert_eq!(Location::Floor(2).storey(3), None);
        assert_eq!(Location::Floor(2).floor(3), Some(2));
        assert_eq!(Location::Number(0).floor(3), None);
        assert_eq!(Location::Between(1, 2).floor(3), None);
        assert_eq!(
            Location::from_numbers(&[2, 3]),
            Some(Location::Between(2, 3))
        );
        assert_eq!(Location::from_numbers(&[1, 2, 3]), None);
        assert_eq!(one_of(1..=3), "1, 2 or 3");
        assert_eq!(one_of(["0-1"]), "0-1");
    }
}
