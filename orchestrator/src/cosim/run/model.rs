//! The run's model: the FMU or the SSP system's components with their modelDescriptions, the
//! start values checked against them (a name not found gets the closest ones suggested) and set.

use std::path::{Path, PathBuf};

use crate::cosim::import::{
    self, Causality, ImportError, Instance, ModelDescription, ScalarType, ScalarVariable,
    UnpackLimits, Unpacked, UnpackedFmu,
};
use crate::cosim::master::PortType;
use crate::cosim::ssp::{self, Connection, SsvValue};

use super::RunError;

pub(super) struct Component {
    /// Instance name (the SSP component's name, or the FMU's model identifier).
    pub(super) name: String,
    /// Prefix of its variables' names in the run: "" for a lone FMU, "name." in a system.
    pub(super) prefix: String,
    pub(super) md: ModelDescription,
    /// Taken when the FMU is loaded.
    pub(super) fmu: Option<UnpackedFmu>,
    /// Start values from the system's parameter bindings, by variable name.
    pub(super) bound: Vec<(String, SsvValue)>,
}

pub(super) struct Model {
    pub(super) path: PathBuf,
    pub(super) components: Vec<Component>,
    pub(super) connections: Vec<Connection>,
    /// The system's input connectors (a system only).
    pub(super) system_inputs: Vec<String>,
    pub(super) default_start: Option<f64>,
    pub(super) default_stop: Option<f64>,
    pub(super) default_step: Option<f64>,
    pub(super) _archive: Option<Unpacked>,
}

pub(super) fn is_ssp(path: &Path) -> Result<bool, RunError> {
    match path.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("ssp") => Ok(true),
        Some(e) if e.eq_ignore_ascii_case("fmu") => Ok(false),
        _ => Err(RunError::Model {
            path: path.to_owned(),
            message: "neither an .fmu nor an .ssp file".into(),
        }),
    }
}

impl Model {
    /// The model at `path`: one FMU, or an SSP archive's system of them.
    pub(super) fn open(path: &Path) -> Result<Self, RunError> {
        if !path.is_file() {
            return Err(RunError::Model {
                path: path.to_owned(),
                message: "no such file".into(),
            });
        }
        if is_ssp(path)? {
            Self::of_system(path)
        } else {
            Self::of_fmu(path)
        }
    }

    /// One FMU: its one component, the experiment its modelDescription gives.
    fn of_fmu(path: &Path) -> Result<Self, RunError> {
        let fmu = UnpackedFmu::open(path)?;
        let md = fmu.model_description.clone();
        let (start, stop, step) = (
            md.default_start_time,
            md.default_stop_time,
            md.default_step_size,
        );
        Ok(Model {
            path: path.to_owned(),
            components: vec![Component {
                name: md.model_identifier.clone(),
                prefix: String::new(),
                md,
                fmu: Some(fmu),
                bound: Vec::new(),
            }],
            connections: Vec::new(),
            system_inputs: Vec::new(),
            default_start: start,
            default_stop: stop,
            default_step: step,
            _archive: None,
        })
    }

    /// An SSP archive: its SystemStructure.ssd's components (each an FMU inside the archive,
    /// with its parameter bindings), connections, system inputs and experiment.
    fn of_system(path: &Path) -> Result<Self, RunError> {
        let bad = |message: String| RunError::Model {
            path: path.to_owned(),
            message,
        };
        let archive = import::unpack(path, UnpackLimits::default())?;
        let read = |inner: &str| {
            std::fs::read_to_string(archive.path().join(inner))
                .map_err(|e| bad(format!("{inner}: {e}")))
        };
        let ssd = ssp::parse_ssd(&read("SystemStructure.ssd")?)
            .map_err(|m| bad(format!("SystemStructure.ssd: {m}")))?;
        let mut components = Vec::new();
        for (i, c) in ssd.components.iter().enumerate() {
            if ssd.components[..i].iter().any(|d| d.name == c.name) {
                return Err(bad(format!("two components are named '{}'", c.name)));
            }
            components.push(system_component(archive.path(), c, &read, &bad)?);
        }
        if components.is_empty() {
            return Err(bad("the system has no components".into()));
        }
        // The smallest of the components' default steps, so no component is stepped coarser
        // than its author meant.
        let default_step = components
            .iter()
            .filter_map(|c| c.md.default_step_size)
            .reduce(f64::min);
        let system_inputs = ssd
            .connectors
            .iter()
            .filter(|c| c.kind == "input")
            .map(|c| c.name.clone())
            .collect();
        Ok(Model {
            path: path.to_owned(),
            components,
            connections: ssd.connections,
            system_inputs,
            default_start: ssd.start_time,
            default_stop: ssd.stop_time,
            default_step,
            _archive: Some(archive),
        })
    }

    pub(super) fn component_index(&self, name: &str) -> Option<usize> {
        self.components.iter().position(|c| c.name == name)
    }

    /// Every variable by its name in the run.
    pub(super) fn variables(&self) -> impl Iterator<Item = (usize, String, &ScalarVariable)> {
        self.components.iter().enumerate().flat_map(|(i, c)| {
            c.md.variables
                .iter()
                .map(move |v| (i, format!("{}{}", c.prefix, v.name), v))
        })
    }

    /// The component inputs a system input connector feeds.
    pub(super) fn fed_by_system_input(&self, connector: &str) -> Vec<(usize, ScalarVariable)> {
        if !self.system_inputs.iter().any(|c| c == connector) {
            return Vec::new();
        }
        self.connections
            .iter()
            .filter(|k| k.start_element.is_none() && k.start_connector == connector)
            .filter_map(|k| {
                let i = self.component_index(k.end_element.as_deref()?)?;
                let v = self.components[i].md.variable(&k.end_connector)?;
                Some((i, v.clone()))
            })
            .collect()
    }

    pub(super) fn find(&self, name: &str) -> Option<(usize, &ScalarVariable)> {
        for (i, c) in self.components.iter().enumerate() {
            if let Some(local) = name.strip_prefix(&c.prefix) {
                if let Some(v) = c.md.variable(local) {
                    return Some((i, v));
                }
            }
        }
        None
    }

    pub(super) fn unknown(&self, what: &str, name: &str, candidates: Vec<String>) -> RunError {
        let close = closest(name, &candidates);
        RunError::Config(format!(
            "{what} '{name}': {} has no such variable{}",
            self.path.display(),
            if close.is_empty() {
                String::new()
            } else {
                format!(" (closest: {})", close.join(", "))
            }
        ))
    }

    pub(super) fn all_variable_names(&self) -> Vec<String> {
        self.variables().map(|(_, n, _)| n).collect()
    }

    pub(super) fn can_vary_step(&self) -> bool {
        self.components
            .iter()
            .all(|c| c.md.can_handle_variable_step)
    }
}

/// The system's component `c`: its FMU (a path inside the archive unpacked at `root`: nothing
/// absolute, no '..', no other scheme) and the values its bindings give. `read` reads a file of
/// the archive, `bad` makes the archive's error.
fn system_component(
    root: &Path,
    c: &ssp::SsdComponent,
    read: &dyn Fn(&str) -> Result<String, RunError>,
    bad: &dyn Fn(String) -> RunError,
) -> Result<Component, RunError> {
    let inside = !c.source.starts_with('/')
        && !c.source.contains(':')
        && !c.source.split('/').any(|part| part == "..");
    let fmu_path = root.join(&c.source);
    if !inside || !fmu_path.is_file() {
        return Err(bad(format!(
            "component '{}': its source '{}' is not in the archive",
            c.name, c.source
        )));
    }
    let fmu = UnpackedFmu::open(&fmu_path).map_err(|e| {
        bad(format!(
            "component '{}' ({}): {}",
            c.name,
            c.source,
            e.to_string()
                .replace(&fmu_path.display().to_string(), "the FMU")
        ))
    })?;
    let mut bound = Vec::new();
    for binding in &c.bindings {
        bound.extend(ssp::parse_ssv(&read(binding)?).map_err(|m| bad(format!("{binding}: {m}")))?);
    }
    Ok(Component {
        name: c.name.clone(),
        prefix: format!("{}.", c.name),
        md: fmu.model_description.clone(),
        fmu: Some(fmu),
        bound,
    })
}

/// Up to three names closest to `name` (by edit distance), for "did you mean".
pub(super) fn closest(name: &str, candidates: &[String]) -> Vec<String> {
    let mut scored: Vec<(usize, &String)> = candidates
        .iter()
        .map(|c| (strsim::levenshtein(name, c), c))
        .filter(|(d, c)| *d <= (name.len().max(c.len()) / 2).max(2))
        .collect();
    scored.sort();
    scored.into_iter().take(3).map(|(_, c)| c.clone()).collect()
}

// ---------------------------------------------------------------------------------------------
// Values

/// A start value or input sample, checked against its variable's type.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Value {
    Number(f64),
    Text(String),
}

pub(super) fn parse_value(variable: &ScalarVariable, text: &str) -> Result<Value, String> {
    let t = text.trim();
    let number = match variable.scalar_type {
        ScalarType::Real => t
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or("a finite Real")?,
        ScalarType::Integer | ScalarType::Enumeration => {
            f64::from(t.parse::<i32>().map_err(|_| "an Integer")?)
        }
        ScalarType::Boolean => match t {
            "1" | "true" | "True" => 1.0,
            "0" | "false" | "False" => 0.0,
            _ => return Err("a Boolean (0, 1, true, false)".into()),
        },
        ScalarType::String => return Ok(Value::Text(text.to_owned())),
    };
    Ok(Value::Number(number))
}

pub(super) fn ssv_value(variable: &ScalarVariable, value: &SsvValue) -> Result<Value, String> {
    match (variable.scalar_type, value) {
        (ScalarType::Real, SsvValue::Real(x)) => Ok(Value::Number(*x)),
        (ScalarType::Real, SsvValue::Integer(i)) => Ok(Value::Number(f64::from(*i))),
        (ScalarType::Integer | ScalarType::Enumeration, SsvValue::Integer(i)) => {
            Ok(Value::Number(f64::from(*i)))
        }
        (ScalarType::Boolean, SsvValue::Boolean(b)) => Ok(Value::Number(f64::from(u8::from(*b)))),
        (ScalarType::String, SsvValue::String(s)) => Ok(Value::Text(s.clone())),
        (ty, v) => Err(format!("is {ty:?}, the parameter set gives {v:?}")),
    }
}

pub(super) fn settable(v: &ScalarVariable) -> bool {
    v.variability != "constant"
        && (matches!(v.causality, Causality::Parameter | Causality::Input)
            || matches!(v.initial.as_deref(), Some("exact" | "approx")))
}

pub(super) fn port_type(t: ScalarType) -> PortType {
    match t {
        ScalarType::Real => PortType::Real,
        ScalarType::Integer | ScalarType::Enumeration => PortType::Integer,
        ScalarType::Boolean => PortType::Boolean,
        ScalarType::String => PortType::String,
    }
}

pub(super) fn set_value(
    instance: &mut Instance,
    v: &ScalarVariable,
    value: &Value,
) -> Result<(), ImportError> {
    let vr = [v.value_reference];
    match (v.scalar_type, value) {
        (ScalarType::String, Value::Text(s)) => instance.set_string(&vr, &[s.as_str()]),
        (ScalarType::Real, Value::Number(x)) => instance.set_real(&vr, &[*x]),
        (ScalarType::Integer | ScalarType::Enumeration, Value::Number(x)) => {
            instance.set_integer(&vr, &[*x as i32])
        }
        (ScalarType::Boolean, Value::Number(x)) => instance.set_boolean(&vr, &[*x != 0.0]),
        // Checked when the configuration was validated.
        _ => Ok(()),
    }
}

// ---------------------------------------------------------------------------------------------
// The input file, resampled as fmpy does

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_names_are_suggested() {
        let names: Vec<String> = ["force", "control_force", "k1", "k2"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        assert_eq!(closest("forse", &names)[0], "force");
        assert!(closest("zzzzzzzz", &names).is_empty());
    }
}
