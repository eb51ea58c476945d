//! The one check of a record against a twin, made before any work by every command that runs a
//! twin on a record (the CLI's and the Python package's alike): the record's excitation is the
//! one the twin's structure takes (`force` for a force at a floor, `ground_acc` for ground
//! motion), and every response channel is one the twin can predict (`acc<i>`, `vel<i>`,
//! `disp<i>` of a floor the structure has). A refusal names the column, the file and its header
//! line, and what the twin is. Commands still written for the paper's rig say so here too
//! ([`check_paper_rig`]), before any work, instead of failing later or answering nonsense.

use ::structure::channel::Channel;
use ::structure::{Excitation, Structure};

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
    /// The command serves the paper's rig only and the twin is another building.
    #[error(
        "twin {command} serves the paper's rig only (3 storeys, a force at floor 1); {twin} is \
         {storeys} storey(s) under {excitation}"
    )]
    PaperRigOnly {
        command: String,
        twin: String,
        storeys: usize,
        excitation: String,
    },
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

/// Whether `structure` is laid out as the paper's rig: three storeys, a force at floor 1 (its
/// masses, dampings and stiffnesses may be any).
pub fn is_paper_rig(structure: &Structure) -> bool {
    structure.storeys() == 3 && structure.excitation == Excitation::Force { floor: 1 }
}

/// For a command still written for the paper's rig (`command`, e.g. "diagnose"): the twin must
/// be laid out as the rig ([`is_paper_rig`]), the record fit it ([`check_record`]) and have the
/// rig's columns, a force and acc1..acc3 ([`Measurement::require_paper_rig`]).
pub fn check_paper_rig(twin: &Twin, data: &Measurement, command: &str) -> Result<(), Refused> {
    let structure = check_record(twin, data)?;
    require_paper_twin(twin, &structure, command)?;
    data.require_paper_rig()?;
    Ok(())
}

/// For a command still written for the paper's rig that takes a twin without a record (or
/// checks its records itself): refused unless the twin is laid out as the rig.
pub fn check_paper_twin(twin: &Twin, command: &str) -> Result<(), Refused> {
    let structure = twin.structure()?;
    require_paper_twin(twin, &structure, command)
}

fn require_paper_twin(twin: &Twin, structure: &Structure, command: &str) -> Result<(), Refused> {
    if is_paper_rig(structure) {
        return Ok(());
    }
    Err(Refused::PaperRigOnly {
        command: command.to_owned(),
        twin: twin.describe(),
        storeys: structure.storeys(),
        excitation: structure.excitation.describe(),
    })
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::record::ColumnMap;

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
        assert!(is_paper_rig(&structure));

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
        assert!(check_paper_rig(
            &twin,
            &record(&["force", "acc1", "acc2", "acc3"]),
            "diagnose"
        )
        .is_ok());
        let e = check_paper_rig(&twin, &record(&["force", "vel1"]), "diagnose")
            .expect_err("no acc1")
            .to_string();
        assert!(e.contains("missing column 'acc1'"), "{e}");
    }

    #[test]
    fn a_twin_of_another_structure_knows_it_and_the_paper_rig_commands_say_so() {
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
        let e = check_paper_twin(&twin, "control")
            .expect_err("five storeys")
            .to_string();
        assert_eq!(
            e,
            format!(
                "twin control serves the paper's rig only (3 storeys, a force at floor 1); {} is \
                 5 storey(s) under ground acceleration at the base",
                twin.describe()
            )
        );
    }
}
