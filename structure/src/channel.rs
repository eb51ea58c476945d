//! What a record measures: its columns (`time`, the excitation, responses `acc<i>`, `vel<i>`,
//! `disp<i>`), each with a unit written in the header as `name (unit)`.

use serde::{Deserialize, Serialize};

use crate::building::{Excitation, Structure};

/// Standard gravity, m/s², for sensors reading in g.
pub const STANDARD_GRAVITY: f64 = 9.80665;

/// What a column measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Quantity {
    Time,
    Force,
    Acceleration,
    Velocity,
    Displacement,
}

impl Quantity {
    /// The SI unit it is read into.
    pub fn si(self) -> Unit {
        match self {
            Quantity::Time => Unit::Second,
            Quantity::Force => Unit::Newton,
            Quantity::Acceleration => Unit::MetrePerSecond2,
            Quantity::Velocity => Unit::MetrePerSecond,
            Quantity::Displacement => Unit::Metre,
        }
    }
}

/// The units a header may name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Unit {
    Second,
    Newton,
    KiloNewton,
    MetrePerSecond2,
    MilliMetrePerSecond2,
    G,
    MetrePerSecond,
    MilliMetrePerSecond,
    Metre,
    MilliMetre,
}

impl Unit {
    pub const ALL: [Unit; 10] = [
        Unit::Second,
        Unit::Newton,
        Unit::KiloNewton,
        Unit::MetrePerSecond2,
        Unit::MilliMetrePerSecond2,
        Unit::G,
        Unit::MetrePerSecond,
        Unit::MilliMetrePerSecond,
        Unit::Metre,
        Unit::MilliMetre,
    ];

    /// As written in a header: `s`, `N`, `kN`, `m/s2`, `mm/s2`, `g`, `m/s`, `mm/s`, `m`, `mm`.
    pub fn symbol(self) -> &'static str {
        match self {
            Unit::Second => "s",
            Unit::Newton => "N",
            Unit::KiloNewton => "kN",
            Unit::MetrePerSecond2 => "m/s2",
            Unit::MilliMetrePerSecond2 => "mm/s2",
            Unit::G => "g",
            Unit::MetrePerSecond => "m/s",
            Unit::MilliMetrePerSecond => "mm/s",
            Unit::Metre => "m",
            Unit::MilliMetre => "mm",
        }
    }

    /// A symbol; `m/s^2` and `m/s²` are taken for `m/s2`.
    pub fn parse(text: &str) -> Option<Unit> {
        let t = text.trim().replace("^2", "2").replace('²', "2");
        Unit::ALL.into_iter().find(|u| u.symbol() == t)
    }

    pub fn quantity(self) -> Quantity {
        match self {
            Unit::Second => Quantity::Time,
            Unit::Newton | Unit::KiloNewton => Quantity::Force,
            Unit::MetrePerSecond2 | Unit::MilliMetrePerSecond2 | Unit::G => Quantity::Acceleration,
            Unit::MetrePerSecond | Unit::MilliMetrePerSecond => Quantity::Velocity,
            Unit::Metre | Unit::MilliMetre => Quantity::Displacement,
        }
    }

    /// SI units per unit: a value in this unit times this is the value in SI.
    pub fn to_si(self) -> f64 {
        match self {
            Unit::Second
            | Unit::Newton
            | Unit::MetrePerSecond2
            | Unit::MetrePerSecond
            | Unit::Metre => 1.0,
            Unit::KiloNewton => 1e3,
            Unit::G => STANDARD_GRAVITY,
            Unit::MilliMetrePerSecond2 | Unit::MilliMetrePerSecond | Unit::MilliMetre => 1e-3,
        }
    }
}

/// One column of a record, named as the twin knows it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Channel {
    Time,
    /// The excitation: `force` (N) or `ground_acc` (m/s²).
    Excitation(ExcitationKind),
    /// A response of floor `floor` (1-based): `acc<i>`, `vel<i>`, `disp<i>`.
    Response {
        quantity: Quantity,
        floor: usize,
    },
}

/// The excitation's column.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ExcitationKind {
    Force,
    GroundAcc,
}

impl ExcitationKind {
    pub fn of(excitation: &Excitation) -> ExcitationKind {
        match excitation {
            Excitation::Force { .. } => ExcitationKind::Force,
            Excitation::Base => ExcitationKind::GroundAcc,
        }
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ChannelError {
    #[error("column '{0}' is not one the twin knows: time, force, ground_acc, acc<i>, vel<i> or disp<i> (i a floor, from 1); map other names with --columns")]
    UnknownName(String),
    #[error("column '{column}': unknown unit '{unit}' (known: {})", Unit::ALL.map(Unit::symbol).join(", "))]
    UnknownUnit { column: String, unit: String },
    #[error("column '{column}': the unit '{unit}' is not one of a {quantity:?}")]
    WrongUnit {
        column: String,
        unit: String,
        quantity: Quantity,
    },
    #[error("column '{column}' is for floor {floor}; the structure has floors 1 to {storeys}")]
    NoSuchFloor {
        column: String,
        floor: usize,
        storeys: usize,
    },
    #[error("column '{column}' is {kind}, but the structure is excited by {excitation}")]
    WrongExcitation {
        column: String,
        kind: &'static str,
        excitation: String,
    },
}

impl Channel {
    /// `time`, `force`, `ground_acc`, `acc<i>`, `vel<i>`, `disp<i>` (i ≥ 1, no leading zero).
    pub fn parse(name: &str) -> Option<Channel> {
        match name {
            "time" => return Some(Channel::Time),
            "force" => return Some(Channel::Excitation(ExcitationKind::Force)),
            "ground_acc" => return Some(Channel::Excitation(ExcitationKind::GroundAcc)),
            _ => {}
        }
        let (quantity, digits) = [
            ("acc", Quantity::Acceleration),
            ("vel", Quantity::Velocity),
            ("disp", Quantity::Displacement),
        ]
        .into_iter()
        .find_map(|(prefix, q)| name.strip_prefix(prefix).map(|d| (q, d)))?;
        if digits.is_empty()
            || digits.starts_with('0')
            || !digits.bytes().all(|b| b.is_ascii_digit())
        {
            return None;
        }
        let floor = digits.parse().ok()?;
        Some(Channel::Response { quantity, floor })
    }

    pub fn name(&self) -> String {
        match self {
            Channel::Time => "time".to_owned(),
            Channel::Excitation(ExcitationKind::Force) => "force".to_owned(),
            Channel::Excitation(ExcitationKind::GroundAcc) => "ground_acc".to_owned(),
            Channel::Response { quantity, floor } => {
                let prefix = match quantity {
                    Quantity::Acceleration => "acc",
                    Quantity::Velocity => "vel",
                    Quantity::Displacement => "disp",
                    Quantity::Time | Quantity::Force => "?",
                };
                format!("{prefix}{floor}")
            }
        }
    }

    pub fn quantity(&self) -> Quantity {
        match self {
            Channel::Time => Quantity::Time,
            Channel::Excitation(ExcitationKind::Force) => Quantity::Force,
            Channel::Excitation(ExcitationKind::GroundAcc) => Quantity::Acceleration,
            Channel::Response { quantity, .. } => *quantity,
        }
    }

    /// Whether `structure` can be driven by (excitation) or predict (response) this column.
    pub fn check(&self, column: &str, structure: &Structure) -> Result<(), ChannelError> {
        match self {
            Channel::Time => Ok(()),
            Channel::Excitation(kind) => {
                if *kind == ExcitationKind::of(&structure.excitation) {
                    Ok(())
                } else {
                    Err(ChannelError::WrongExcitation {
                        column: column.to_owned(),
                        kind: match kind {
                            ExcitationKind::Force => "a force",
                            ExcitationKind::GroundAcc => "a ground acceleration",
                        },
                        excitation: structure.excitation.describe(),
                    })
                }
            }
            Channel::Response { floor, .. } => {
                if (1..=structure.storeys()).contains(floor) {
                    Ok(())
                } else {
                    Err(ChannelError::NoSuchFloor {
                        column: column.to_owned(),
                        floor: *floor,
                        storeys: structure.storeys(),
                    })
                }
            }
        }
    }
}

/// A header field `name (unit)` or `name`: the channel and its unit (SI when none is written).
pub fn parse_header_field(field: &str) -> Result<(Channel, Unit), ChannelError> {
    let field = field.trim();
    let (name, unit) = split_unit(field);
    let channel =
        Channel::parse(name).ok_or_else(|| ChannelError::UnknownName(field.to_owned()))?;
    let quantity = channel.quantity();
    let unit = match unit {
        None => quantity.si(),
        Some(text) => {
            let unit = Unit::parse(text).ok_or_else(|| ChannelError::UnknownUnit {
                column: field.to_owned(),
                unit: text.to_owned(),
            })?;
            if unit.quantity() != quantity {
                return Err(ChannelError::WrongUnit {
                    column: field.to_owned(),
                    unit: text.to_owned(),
                    quantity,
                });
            }
            unit
        }
    };
    Ok((channel, unit))
}

/// `acc1 (g)` → (`acc1`, Some(`g`)); `acc1` → (`acc1`, None).
pub fn split_unit(field: &str) -> (&str, Option<&str>) {
    let field = field.trim();
    match (field.find('('), field.strip_suffix(')')) {
        (Some(open), Some(inner)) => (field[..open].trim(), Some(inner[open + 1..].trim())),
        _ => (field, None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_fields_with_and_without_units() {
        assert_eq!(
            parse_header_field("acc2 (g)").unwrap(),
            (
                Channel::Response {
                    quantity: Quantity::Acceleration,
                    floor: 2
                },
                Unit::G
            )
        );
        assert_eq!(
            parse_header_field("vel10(mm/s)").unwrap().1,
            Unit::MilliMetrePerSecond
        );
        assert_eq!(parse_header_field("force").unwrap().1, Unit::Newton);
        assert_eq!(
            parse_header_field("ground_acc (m/s^2)").unwrap().1,
            Unit::MetrePerSecond2
        );
        assert!(matches!(
            parse_header_field("acc1 (in/s2)"),
            Err(ChannelError::UnknownUnit { .. })
        ));
        assert!(matches!(
            parse_header_field("disp1 (g)"),
            Err(ChannelError::WrongUnit { .. })
        ));
        for bad in ["acc0", "acc01", "acc", "strain1", "accx"] {
            assert!(parse_header_field(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn names_round_trip() {
        for name in ["time", "force", "ground_acc", "acc1", "vel12", "disp3"] {
            assert_eq!(Channel::parse(name).unwrap().name(), name);
        }
    }

    #[test]
    fn a_column_the_structure_cannot_use_is_refused_by_name() {
        let s = Structure::default();
        let four = Channel::parse("acc4").unwrap();
        let e = four.check("acc4 (g)", &s).unwrap_err().to_string();
        assert!(
            e.contains("'acc4 (g)'") && e.contains("floors 1 to 3"),
            "{e}"
        );
        let g = Channel::parse("ground_acc").unwrap();
        assert!(g.check("ground_acc", &s).is_err());
        assert!(Channel::parse("force").unwrap().check("force", &s).is_ok());
    }

    #[test]
    fn units_convert_to_si() {
        assert_eq!(Unit::G.to_si(), STANDARD_GRAVITY);
        assert_eq!(Unit::KiloNewton.to_si(), 1e3);
        assert_eq!(Unit::MilliMetre.to_si(), 1e-3);
    }
}
