//! The one check of a record against a twin, made before any work by every command that runs a
//! twin on a record (the CLI's and the Python package's alike): the record's excitation is the
//! one the twin's structure takes (`force` for a force at a floor, `ground_acc` for ground
//! motion), and every response channel is one the twin can predict (`acc<i>`, `vel<i>`,
//! `disp<i>` of a floor the structure has). A refusal names the column, the file and its header
//! line, and what the twin is.

use ::structure::channel::Channel;
use ::structure::Structure;

use super::{Twin, TwinError};
use crate::record::{DataError, Measurement};

/// Why a record or a twin was refused.
#[derive(Debug, thiserror::Error)]
pub enum Refused {
    /// The record does not fit the twin: the message names the column.
    #[error(transparent)]
    Record(#[from] DataError),
    /// The twin's structure could not be read.
    #[error(transparent)]
    Twin(#[from] TwinError),
}

/// `storeys` storey(s) under `excitation`, in words.
fn describe(structure: &Structure) -> String {
    format!(
        "{} storey(s) under {}",
        structure.storeys(),
        structure.excitation.describe()
    )
}

/// Check `data` against `twin` (see the module's note) and return the twin's structure.
pub fn check_record(twin: &Twin, data: &Measurement) -> Result<Structure, Refused> {
    let structure = twin.structure()?;
    check_against(&structure, &twin.describe(), data)?;
    Ok(structure)
}

/// [`check_record`] against a structure known already; `twin` names it in the message.
pub fn check_against(
    structure: &Structure,
    twin: &str,
    data: &Measurement,
) -> Result<(), DataError> {
    for signal in data.channels() {
        let channel: &Channel = &signal.channel;
        channel
            .check(&channel.name(), structure)
            .map_err(|e| DataError {
                path: data.path.clone(),
                line: data.header_line,
                message: format!("{e} (the twin: {twin}, {})", describe(structure)),
            })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::record::ColumnMap;
    use ::structure::Excitation;

    /// A 20-sample record with the named columns (all zeros but a ramp of time).
    fn record(names: &[&str]) -> Measurement {
        let time: Vec<f64> = (0..20).map(|k| k as f64 * 0.01).collect();
        let mut named = vec![("time".to_owned(), time)];
        for name in names {
            named.push(((*name).to_owned(), vec![0.0; 20]));
        }
        Measurement::from_named_columns(Path::new("r.csv"), named, &ColumnMap::default())
            .expect("a record")
    }

    fn refusal(twin: &Twin, names: &[&str]) -> String {
        check_record(twin, &record(names))
            .expect_err("refused")
            .to_string()
    }

    #[test]
    fn the_paper_twin_takes_its_channels_and_refuses_others_naming_the_column() {
        let twin = Twin::default_twin().expect("the default twin");
        let structure = check_record(&twin, &record(&["force", "acc1", "vel3", "disp2"]))
            .expect("a force and floors 1 to 3");
        assert_eq!(structure, Structure::default());

        let e = refusal(&twin, &["force", "acc1", "acc4"]);
        assert!(
            e.starts_with("r.csv: column 'acc4' is for floor 4; the structure has floors 1 to 3"),
            "{e}"
        );
        let e = refusal(&twin, &["ground_acc", "acc1"]);
        assert!(
            e.contains("column 'ground_acc' is a ground acceleration"),
            "{e}"
        );
        assert!(e.contains("a force at floor 1"), "{e}");
    }

    #[test]
    fn a_twin_of_another_structure_knows_it() {
        let five = Structure::uniform(5, 2.0, 1.0, 3000.0, Excitation::Base);
        let twin = Twin::for_structure(&five).expect("a five-storey twin");
        assert_eq!(twin.structure().expect("its structure"), five);
        assert!(check_record(&twin, &record(&["ground_acc", "acc5", "vel2"])).is_ok());
        let e = refusal(&twin, &["force", "acc1"]);
        assert!(e.contains("column 'force' is a force"), "{e}");
        assert!(e.contains("ground acceleration at the base"), "{e}");
        let e = refusal(&twin, &["ground_acc", "acc7"]);
        assert!(
            e.contains("column 'acc7' is for floor 7; the structure has floors 1 to 5"),
            "{e}"
        );
    }
}
