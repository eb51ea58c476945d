//! `modelDescription.xml` of an FMI 2.0 FMU, read with quick-xml + serde into typed structs,
//! then checked for what the orchestrator relies on.

use std::collections::HashMap;
use std::path::Path;

use serde::Deserialize;

use super::ImportError;

#[derive(Debug, Deserialize)]
struct RawModelDescription {
    #[serde(rename = "@fmiVersion")]
    fmi_version: String,
    #[serde(rename = "@modelName")]
    model_name: String,
    #[serde(rename = "@guid")]
    guid: String,
    #[serde(rename = "CoSimulation")]
    co_simulation: Option<RawCoSimulation>,
    #[serde(rename = "DefaultExperiment")]
    default_experiment: Option<RawDefaultExperiment>,
    #[serde(rename = "ModelVariables")]
    model_variables: Option<RawModelVariables>,
}

#[derive(Debug, Deserialize)]
struct RawCoSimulation {
    #[serde(rename = "@modelIdentifier")]
    model_identifier: String,
    #[serde(rename = "@canInterpolateInputs", default)]
    can_interpolate_inputs: Option<bool>,
    #[serde(rename = "@canGetAndSetFMUstate", default)]
    can_get_and_set_fmu_state: Option<bool>,
    #[serde(rename = "@canSerializeFMUstate", default)]
    can_serialize_fmu_state: Option<bool>,
    #[serde(rename = "@canHandleVariableCommunicationStepSize", default)]
    can_handle_variable_step: Option<bool>,
}

#[derive(Debug, Deserialize)]
struct RawDefaultExperiment {
    #[serde(rename = "@startTime")]
    start_time: Option<f64>,
    #[serde(rename = "@stopTime")]
    stop_time: Option<f64>,
    #[serde(rename = "@stepSize")]
    step_size: Option<f64>,
}

#[derive(Debug, Deserialize)]
struct RawModelVariables {
    #[serde(rename = "ScalarVariable", default)]
    variables: Vec<RawScalarVariable>,
}

#[derive(Debug, Deserialize)]
struct RawScalarVariable {
    #[serde(rename = "@name")]
    name: String,
    #[serde(rename = "@valueReference")]
    value_reference: u32,
    #[serde(rename = "@causality", default)]
    causality: Option<String>,
    #[serde(rename = "@variability", default)]
    variability: Option<String>,
    #[serde(rename = "@initial", default)]
    initial: Option<String>,
    #[serde(rename = "Real")]
    real: Option<RawTypeAttrs>,
    #[serde(rename = "Integer")]
    integer: Option<RawTypeAttrs>,
    #[serde(rename = "Boolean")]
    boolean: Option<RawTypeAttrs>,
    #[serde(rename = "String")]
    string: Option<RawTypeAttrs>,
    #[serde(rename = "Enumeration")]
    enumeration: Option<RawTypeAttrs>,
}

#[derive(Debug, Deserialize)]
struct RawTypeAttrs {
    #[serde(rename = "@start")]
    start: Option<String>,
    #[serde(rename = "@unit")]
    unit: Option<String>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScalarType {
    Real,
    Integer,
    Boolean,
    String,
    Enumeration,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Causality {
    Parameter,
    CalculatedParameter,
    Input,
    Output,
    Local,
    Independent,
}

#[derive(Debug, Clone)]
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

#[derive(Debug, Clone)]
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
    by_name: HashMap<String, usize>,
}

impl ModelDescription {
    pub fn parse(xml: &str, path: &Path) -> Result<Self, ImportError> {
        let bad = |message: String| ImportError::ModelDescription {
            path: path.to_owned(),
            message,
        };
        let raw: RawModelDescription =
            quick_xml::de::from_str(xml).map_err(|e| bad(format!("malformed: {e}")))?;
        if !raw.fmi_version.starts_with("2.") {
            return Err(bad(format!(
                "fmiVersion is '{}'; only FMI 2.0 is supported",
                raw.fmi_version
            )));
        }
        let cs = raw
            .co_simulation
            .ok_or_else(|| bad("no CoSimulation element: not a co-simulation FMU".into()))?;
        if cs.model_identifier.is_empty() || cs.model_identifier.contains(['/', '\\', '.']) {
            return Err(bad(format!(
                "modelIdentifier '{}' is not a valid file stem",
                cs.model_identifier
            )));
        }
        let mut variables = Vec::new();
        let mut by_name = HashMap::new();
        for v in raw.model_variables.map(|m| m.variables).unwrap_or_default() {
            let (scalar_type, attrs) =
                match (&v.real, &v.integer, &v.boolean, &v.string, &v.enumeration) {
                    (Some(a), None, None, None, None) => (ScalarType::Real, a),
                    (None, Some(a), None, None, None) => (ScalarType::Integer, a),
                    (None, None, Some(a), None, None) => (ScalarType::Boolean, a),
                    (None, None, None, Some(a), None) => (ScalarType::String, a),
                    (None, None, None, None, Some(a)) => (ScalarType::Enumeration, a),
                    _ => {
                        return Err(bad(format!(
                            "variable '{}' must have exactly one type element",
                            v.name
                        )))
                    }
                };
            let causality = match v.causality.as_deref().unwrap_or("local") {
                "parameter" => Causality::Parameter,
                "calculatedParameter" => Causality::CalculatedParameter,
                "input" => Causality::Input,
                "output" => Causality::Output,
                "local" => Causality::Local,
                "independent" => Causality::Independent,
                other => {
                    return Err(bad(format!(
                        "variable '{}' has unknown causality '{other}'",
                        v.name
                    )))
                }
            };
            if by_name.insert(v.name.clone(), variables.len()).is_some() {
                return Err(bad(format!("variable name '{}' appears twice", v.name)));
            }
            variables.push(ScalarVariable {
                name: v.name,
                value_reference: v.value_reference,
                scalar_type,
                causality,
                variability: v.variability.unwrap_or_else(|| "continuous".into()),
                initial: v.initial,
                start: attrs.start.clone(),
                unit: attrs.unit.clone(),
            });
        }
        let de = raw.default_experiment;
        Ok(ModelDescription {
            fmi_version: raw.fmi_version,
            model_name: raw.model_name,
            guid: raw.guid,
            model_identifier: cs.model_identifier,
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
}
