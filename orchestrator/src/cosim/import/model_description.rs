//! `modelDescription.xml` of an FMI 2.0 FMU, read as a stream of quick-xml events into typed
//! structs (one pass, no intermediate tree: a 20-storey shear model describes 1,601
//! variables), then checked for what the orchestrator relies on.

use std::collections::HashMap;
use std::path::Path;

use quick_xml::events::{BytesStart, Event};
use quick_xml::Reader;

use super::ImportError;

/// The root's attributes, as read.
#[derive(Default)]
struct RawRoot {
    fmi_version: Option<String>,
    model_name: Option<String>,
    guid: Option<String>,
}

#[derive(Default)]
struct RawCoSimulation {
    model_identifier: Option<String>,
    can_interpolate_inputs: Option<bool>,
    can_get_and_set_fmu_state: Option<bool>,
    can_serialize_fmu_state: Option<bool>,
    can_handle_variable_step: Option<bool>,
}

#[derive(Default)]
struct RawDefaultExperiment {
    start_time: Option<f64>,
    stop_time: Option<f64>,
    step_size: Option<f64>,
}

/// A `<ScalarVariable>` being read: its attributes, then its type element's.
struct RawScalarVariable {
    name: String,
    value_reference: u32,
    causality: Option<String>,
    variability: Option<String>,
    initial: Option<String>,
    /// The type elements inside it (exactly one is valid) and the first one's attributes.
    types: Vec<ScalarType>,
    start: Option<String>,
    unit: Option<String>,
}

/// Everything the file says that [`ModelDescription::parse`] checks.
#[derive(Default)]
struct RawModelDescription {
    root: Option<RawRoot>,
    co_simulation: Option<RawCoSimulation>,
    default_experiment: Option<RawDefaultExperiment>,
    variables: Vec<RawScalarVariable>,
}

/// An element's attributes as (name, unescaped value) pairs.
fn attributes(e: &BytesStart) -> Result<Vec<(String, String)>, String> {
    e.attributes()
        .map(|a| {
            let a = a.map_err(|e| e.to_string())?;
            let key = String::from_utf8_lossy(a.key.as_ref()).into_owned();
            let value = a.unescape_value().map_err(|e| e.to_string())?.into_owned();
            Ok((key, value))
        })
        .collect()
}

fn parse_bool(name: &str, text: &str) -> Result<bool, String> {
    match text.trim() {
        "true" | "1" => Ok(true),
        "false" | "0" => Ok(false),
        other => Err(format!("{name}=\"{other}\" is not a boolean")),
    }
}

fn parse_real(name: &str, text: &str) -> Result<f64, String> {
    text.trim()
        .parse()
        .map_err(|_| format!("{name}=\"{text}\" is not a number"))
}

impl RawModelDescription {
    /// One pass over the events: the root, `CoSimulation`, `DefaultExperiment` and each
    /// `ModelVariables/ScalarVariable` with its type element; everything else skipped.
    fn read(xml: &str) -> Result<Self, String> {
        let mut reader = Reader::from_str(xml);
        let mut raw = RawModelDescription::default();
        // The open elements' names, the root first.
        let mut open: Vec<Vec<u8>> = Vec::new();
        loop {
            let at = reader.buffer_position();
            let event = reader
                .read_event()
                .map_err(|e| format!("line {}: {e}", line_of(xml, at)))?;
            let (element, empty) = match &event {
                Event::Start(e) => (e, false),
                Event::Empty(e) => (e, true),
                Event::End(_) => {
                    open.pop();
                    continue;
                }
                Event::Eof => break,
                _ => continue,
            };
            let name = element.name().as_ref().to_vec();
            raw.element(&open, &name, element)
                .map_err(|e| format!("line {}: {e}", line_of(xml, at)))?;
            if !empty {
                open.push(name);
            }
        }
        if !open.is_empty() {
            return Err("the file ends inside an element".into());
        }
        Ok(raw)
    }

    /// An element opened inside `open` (the names of its ancestors).
    fn element(&mut self, open: &[Vec<u8>], name: &[u8], e: &BytesStart) -> Result<(), String> {
        let parent = open.last().map(Vec::as_slice);
        match (open.len(), parent, name) {
            (0, _, b"fmiModelDescription") => self.root = Some(root(e)?),
            (0, _, other) => {
                return Err(format!(
                    "the root element is <{}>, not <fmiModelDescription>",
                    String::from_utf8_lossy(other)
                ))
            }
            (1, _, b"CoSimulation") => self.co_simulation = Some(co_simulation(e)?),
            (1, _, b"DefaultExperiment") => self.default_experiment = Some(default_experiment(e)?),
            (2, Some(b"ModelVariables"), b"ScalarVariable") => {
                self.variables.push(scalar_variable(e)?)
            }
            (3, Some(b"ScalarVariable"), kind) if open[1] == b"ModelVariables" => {
                let scalar_type = match kind {
                    b"Real" => ScalarType::Real,
                    b"Integer" => ScalarType::Integer,
                    b"Boolean" => ScalarType::Boolean,
                    b"String" => ScalarType::String,
                    b"Enumeration" => ScalarType::Enumeration,
                    _ => return Ok(()),
                };
                let v = self.variables.last_mut().expect("inside a ScalarVariable");
                if v.types.is_empty() {
                    for (key, value) in attributes(e)? {
                        match key.as_str() {
                            "start" => v.start = Some(value),
                            "unit" => v.unit = Some(value),
                            _ => {}
                        }
                    }
                }
                v.types.push(scalar_type);
            }
            _ => {}
        }
        Ok(())
    }
}

fn root(e: &BytesStart) -> Result<RawRoot, String> {
    let mut r = RawRoot::default();
    for (key, value) in attributes(e)? {
        match key.as_str() {
            "fmiVersion" => r.fmi_version = Some(value),
            "modelName" => r.model_name = Some(value),
            "guid" => r.guid = Some(value),
            _ => {}
        }
    }
    Ok(r)
}

fn co_simulation(e: &BytesStart) -> Result<RawCoSimulation, String> {
    let mut cs = RawCoSimulation::default();
    for (key, value) in attributes(e)? {
        let flag = || parse_bool(&key, &value).map(Some);
        match key.as_str() {
            "modelIdentifier" => cs.model_identifier = Some(value.clone()),
            "canInterpolateInputs" => cs.can_interpolate_inputs = flag()?,
            "canGetAndSetFMUstate" => cs.can_get_and_set_fmu_state = flag()?,
            "canSerializeFMUstate" => cs.can_serialize_fmu_state = flag()?,
            "canHandleVariableCommunicationStepSize" => cs.can_handle_variable_step = flag()?,
            _ => {}
        }
    }
    Ok(cs)
}

fn default_experiment(e: &BytesStart) -> Result<RawDefaultExperiment, String> {
    let mut d = RawDefaultExperiment::default();
    for (key, value) in attributes(e)? {
        let real = || parse_real(&key, &value).map(Some);
        match key.as_str() {
            "startTime" => d.start_time = real()?,
            "stopTime" => d.stop_time = real()?,
            "stepSize" => d.step_size = real()?,
            _ => {}
        }
    }
    Ok(d)
}

fn scalar_variable(e: &BytesStart) -> Result<RawScalarVariable, String> {
    let (mut name, mut value_reference) = (None, None);
    let mut v = RawScalarVariable {
        name: String::new(),
        value_reference: 0,
        causality: None,
        variability: None,
        initial: None,
        types: Vec::new(),
        start: None,
        unit: None,
    };
    for (key, value) in attributes(e)? {
        match key.as_str() {
            "name" => name = Some(value),
            "valueReference" => {
                value_reference = Some(value.trim().parse::<u32>().map_err(|_| {
                    format!("valueReference=\"{value}\" is not an unsigned 32-bit integer")
                })?)
            }
            "causality" => v.causality = Some(value),
            "variability" => v.variability = Some(value),
            "initial" => v.initial = Some(value),
            _ => {}
        }
    }
    v.name = name.ok_or("a ScalarVariable has no name")?;
    v.value_reference =
        value_reference.ok_or_else(|| format!("variable '{}' has no valueReference", v.name))?;
    Ok(v)
}

/// The 1-based line of byte `offset` in `text`.
fn line_of(text: &str, offset: u64) -> usize {
    let end = (offset as usize).min(text.len());
    1 + text.as_bytes()[..end]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum ScalarType {
    Real,
    Integer,
    Boolean,
    String,
    Enumeration,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Causality {
    Parameter,
    CalculatedParameter,
    Input,
    Output,
    Local,
    Independent,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct ScalarVariable {
    pub name: String,
    pub value_reference: u32,
    pub scalar_type: ScalarType,
    pub causality: Causality,
    pub variability: String,
    /// `exact`, `approx` or `calculated`, when the modelDescription says.
    pub initial: Option<String>,
    pub start: Option<String>,
    pub unit: Option<String>,
}

/// What the host reads of a modelDescription.xml. Kept in the FMU cache beside the file it was
/// read from ([`ModelDescription::read_cached`]): a change of these fields changes
/// [`CACHED_FORMAT`].
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct ModelDescription {
    pub fmi_version: String,
    pub model_name: String,
    pub guid: String,
    pub model_identifier: String,
    pub can_interpolate_inputs: bool,
    pub can_get_and_set_fmu_state: bool,
    pub can_serialize_fmu_state: bool,
    pub can_handle_variable_step: bool,
    pub default_step_size: Option<f64>,
    pub default_stop_time: Option<f64>,
    pub default_start_time: Option<f64>,
    pub variables: Vec<ScalarVariable>,
    #[serde(skip)]
    by_name: HashMap<String, usize>,
}

/// The name of the parsed description's file in an FMU cache entry; the number is the layout's
/// version of [`ModelDescription`] and its variables (raised with any change to their fields).
pub const CACHED_FORMAT: &str = "modelDescription.1.postcard";

impl ModelDescription {
    pub fn parse(xml: &str, path: &Path) -> Result<Self, ImportError> {
        let bad = |message: String| ImportError::ModelDescription {
            path: path.to_owned(),
            message,
        };
        let raw = RawModelDescription::read(xml).map_err(|e| bad(format!("malformed: {e}")))?;
        let root = raw
            .root
            .ok_or_else(|| bad("malformed: no fmiModelDescription element".into()))?;
        let required = |value: Option<String>, what: &str| {
            value.ok_or_else(|| bad(format!("malformed: fmiModelDescription has no {what}")))
        };
        let fmi_version = required(root.fmi_version, "fmiVersion")?;
        let model_name = required(root.model_name, "modelName")?;
        let guid = required(root.guid, "guid")?;
        if !fmi_version.starts_with("2.") {
            return Err(bad(format!(
                "fmiVersion is '{fmi_version}'; only FMI 2.0 is supported"
            )));
        }
        let cs = raw
            .co_simulation
            .ok_or_else(|| bad("no CoSimulation element: not a co-simulation FMU".into()))?;
        let model_identifier = cs
            .model_identifier
            .ok_or_else(|| bad("malformed: CoSimulation has no modelIdentifier".into()))?;
        if model_identifier.is_empty() || model_identifier.contains(['/', '\\', '.']) {
            return Err(bad(format!(
                "modelIdentifier '{model_identifier}' is not a valid file stem"
            )));
        }
        let (variables, by_name) = checked_variables(raw.variables).map_err(bad)?;
        let de = raw.default_experiment;
        Ok(ModelDescription {
            fmi_version,
            model_name,
            guid,
            model_identifier,
            can_interpolate_inputs: cs.can_interpolate_inputs.unwrap_or(false),
            can_get_and_set_fmu_state: cs.can_get_and_set_fmu_state.unwrap_or(false),
            can_serialize_fmu_state: cs.can_serialize_fmu_state.unwrap_or(false),
            can_handle_variable_step: cs.can_handle_variable_step.unwrap_or(false),
            default_step_size: de.as_ref().and_then(|d| d.step_size),
            default_stop_time: de.as_ref().and_then(|d| d.stop_time),
            default_start_time: de.as_ref().and_then(|d| d.start_time),
            variables,
            by_name,
        })
    }

    /// The description of the FMU unpacked in `dir`, an entry of the FMU cache: read from the
    /// entry's parsed copy ([`CACHED_FORMAT`]) when it has one, else parsed from its
    /// modelDescription.xml (`path` the archive, for errors) and the parsed copy written beside
    /// it for the next process (a 20-storey shear model's description is 621 kB of XML; its
    /// parsed copy reads in a fraction of the time). The entry's key covers the XML's bytes, so
    /// the copy cannot describe another file; an unreadable copy is parsed again.
    pub fn read_cached(dir: &Path, path: &Path) -> Result<Self, ImportError> {
        let cached = dir.join(CACHED_FORMAT);
        if let Some(description) = std::fs::read(&cached)
            .ok()
            .and_then(|bytes| postcard::from_bytes::<ModelDescription>(&bytes).ok())
            .and_then(ModelDescription::indexed)
        {
            return Ok(description);
        }
        let description = Self::read_file(&dir.join("modelDescription.xml"), path)?;
        if let Ok(bytes) = postcard::to_stdvec(&description) {
            // Another process may write the same copy at once: each writes its own temporary
            // file and renames it; a failure only means the next process parses again.
            let _ = crate::fsutil::write_atomically(&cached, |file| {
                std::io::Write::write_all(file, &bytes)
            });
        }
        Ok(description)
    }

    /// The description in the file `md_path`, of the archive `path` (for errors).
    pub fn read_file(md_path: &Path, path: &Path) -> Result<Self, ImportError> {
        let xml = std::fs::read_to_string(md_path).map_err(|e| ImportError::Archive {
            path: path.to_owned(),
            message: format!("no readable modelDescription.xml: {e}"),
        })?;
        Self::parse(&xml, path)
    }

    /// The name index of a description read from its parsed copy; None when two variables
    /// share a name (not a copy this host wrote).
    fn indexed(mut self) -> Option<Self> {
        let mut by_name = HashMap::with_capacity(self.variables.len());
        for (i, v) in self.variables.iter().enumerate() {
            if by_name.insert(v.name.clone(), i).is_some() {
                return None;
            }
        }
        self.by_name = by_name;
        Some(self)
    }

    pub fn variable(&self, name: &str) -> Option<&ScalarVariable> {
        self.by_name.get(name).map(|&i| &self.variables[i])
    }

    pub fn outputs(&self) -> impl Iterator<Item = &ScalarVariable> {
        self.variables
            .iter()
            .filter(|v| v.causality == Causality::Output)
    }

    pub fn inputs(&self) -> impl Iterator<Item = &ScalarVariable> {
        self.variables
            .iter()
            .filter(|v| v.causality == Causality::Input)
    }
}

/// The variables, each with exactly one type element and a known causality, names unique; and
/// each name's index.
fn checked_variables(
    raw: Vec<RawScalarVariable>,
) -> Result<(Vec<ScalarVariable>, HashMap<String, usize>), String> {
    let mut variables = Vec::with_capacity(raw.len());
    let mut by_name = HashMap::with_capacity(raw.len());
    for v in raw {
        let [scalar_type] = v.types[..] else {
            return Err(format!(
                "variable '{}' must have exactly one type element",
                v.name
            ));
        };
        let causality = match v.causality.as_deref().unwrap_or("local") {
            "parameter" => Causality::Parameter,
            "calculatedParameter" => Causality::CalculatedParameter,
            "input" => Causality::Input,
            "output" => Causality::Output,
            "local" => Causality::Local,
            "independent" => Causality::Independent,
            other => {
                return Err(format!(
                    "variable '{}' has unknown causality '{other}'",
                    v.name
                ))
            }
        };
        if by_name.insert(v.name.clone(), variables.len()).is_some() {
            return Err(format!("variable name '{}' appears twice", v.name));
        }
        variables.push(ScalarVariable {
            name: v.name,
            value_reference: v.value_reference,
            scalar_type,
            causality,
            variability: v.variability.unwrap_or_else(|| "continuous".into()),
            initial: v.initial,
            start: v.start,
            unit: v.unit,
        });
    }
    Ok((variables, by_name))
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINIMAL: &str = r#"<?xml version="1.0"?>
<fmiModelDescription fmiVersion="2.0" modelName="m" guid="{g}">
  <CoSimulation modelIdentifier="m" canInterpolateInputs="true"/>
  <ModelVariables>
    <ScalarVariable name="u" valueReference="1" causality="input"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="y" valueReference="2" causality="output"><Real unit="m"/></ScalarVariable>
    <ScalarVariable name="on" valueReference="3" causality="parameter" variability="fixed"><Boolean start="false"/></ScalarVariable>
  </ModelVariables>
</fmiModelDescription>"#;

    #[test]
    fn reads_variables_and_capabilities() {
        let md = ModelDescription::parse(MINIMAL, Path::new("m.xml")).expect("parses");
        assert_eq!(md.guid, "{g}");
        assert!(md.can_interpolate_inputs);
        assert_eq!(
            md.variable("y").map(|v| v.causality),
            Some(Causality::Output)
        );
        assert_eq!(
            md.variable("on").map(|v| v.scalar_type),
            Some(ScalarType::Boolean)
        );
        assert_eq!(md.inputs().count(), 1);
    }

    #[test]
    fn refuses_malformed_and_unsupported() {
        let err = ModelDescription::parse("<fmiModelDescription", Path::new("x.xml"))
            .expect_err("malformed");
        assert!(err.to_string().contains("x.xml"), "{err}");
        let fmi3 = MINIMAL.replace("fmiVersion=\"2.0\"", "fmiVersion=\"3.0\"");
        assert!(ModelDescription::parse(&fmi3, Path::new("x.xml")).is_err());
        let me = MINIMAL.replace(
            "<CoSimulation modelIdentifier=\"m\" canInterpolateInputs=\"true\"/>",
            "",
        );
        let err = ModelDescription::parse(&me, Path::new("x.xml")).expect_err("no CS");
        assert!(err.to_string().contains("co-simulation"), "{err}");
        let dup = MINIMAL.replace("name=\"y\"", "name=\"u\"");
        assert!(ModelDescription::parse(&dup, Path::new("x.xml")).is_err());
    }

    #[test]
    fn says_which_line_and_which_variable_is_wrong() {
        let two_types = MINIMAL.replace(r#"<Real unit="m"/>"#, r#"<Real unit="m"/><Integer/>"#);
        let err = ModelDescription::parse(&two_types, Path::new("x.xml")).expect_err("two types");
        assert!(
            err.to_string().contains("'y' must have exactly one type"),
            "{err}"
        );
        let vr = MINIMAL.replace(r#"valueReference="2""#, r#"valueReference="-2""#);
        let err = ModelDescription::parse(&vr, Path::new("x.xml")).expect_err("negative vr");
        assert!(err.to_string().contains("line 6"), "{err}");
        let flag = MINIMAL.replace(
            r#"canInterpolateInputs="true""#,
            r#"canInterpolateInputs="yes""#,
        );
        let err = ModelDescription::parse(&flag, Path::new("x.xml")).expect_err("not a bool");
        assert!(err.to_string().contains("canInterpolateInputs"), "{err}");
        let unclosed = MINIMAL.replace("</fmiModelDescription>", "");
        assert!(ModelDescription::parse(&unclosed, Path::new("x.xml")).is_err());
        let no_guid = MINIMAL.replace(r#" guid="{g}""#, "");
        let err = ModelDescription::parse(&no_guid, Path::new("x.xml")).expect_err("no guid");
        assert!(err.to_string().contains("no guid"), "{err}");
        let escaped = MINIMAL.replace(r#"name="u""#, r#"name="u&amp;v""#);
        let md = ModelDescription::parse(&escaped, Path::new("x.xml")).expect("escaped name");
        assert!(md.variable("u&v").is_some());
    }

    /// The cache entry's parsed copy: written by the first read, read by the next (the same
    /// variables, references, types and index by name), and a copy that does not read back (here
    /// garbage) parsed again from the XML and rewritten.
    #[test]
    fn a_cache_entry_keeps_the_parsed_description() {
        let dir = tempfile::tempdir().expect("temporary directory");
        std::fs::write(dir.path().join("modelDescription.xml"), MINIMAL).expect("written");
        let archive = Path::new("m.fmu");
        let first = ModelDescription::read_cached(dir.path(), archive).expect("parsed");
        let copy = dir.path().join(CACHED_FORMAT);
        assert!(copy.is_file(), "the parsed copy is written beside the XML");
        // The XML gone: the second read can only have come from the copy.
        std::fs::remove_file(dir.path().join("modelDescription.xml")).expect("removed");
        let second = ModelDescription::read_cached(dir.path(), archive).expect("from the copy");
        let summary = |md: &ModelDescription| {
            md.variables
                .iter()
                .map(|v| {
                    (
                        v.name.clone(),
                        v.value_reference,
                        v.scalar_type,
                        v.causality,
                    )
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(summary(&first), summary(&second));
        assert_eq!((first.guid.as_str(), second.guid.as_str()), ("{g}", "{g}"));
        assert_eq!(second.variable("y").map(|v| v.value_reference), Some(2));
        std::fs::write(dir.path().join("modelDescription.xml"), MINIMAL).expect("written");
        std::fs::write(&copy, b"not a description").expect("spoiled");
        let third = ModelDescription::read_cached(dir.path(), archive).expect("parsed again");
        assert_eq!(summary(&first), summary(&third));
        assert_ne!(
            std::fs::read(&copy).expect("rewritten"),
            b"not a description"
        );
    }
}
