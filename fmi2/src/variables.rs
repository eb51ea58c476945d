//! The variable table of a model: names, value references, causality, variability, start values
//! and units. The export layer checks every get/set against it, and `to_model_description_xml`
//! turns it into the FMU's `modelDescription.xml`, so the two cannot disagree.

use std::collections::HashMap;
use std::fmt::Write as _;

use quick_xml::events::{BytesDecl, BytesEnd, BytesStart, Event};
use quick_xml::Writer;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum VarType {
    Real,
    Integer,
    Boolean,
    String,
}

impl VarType {
    pub fn xml_name(self) -> &'static str {
        match self {
            VarType::Real => "Real",
            VarType::Integer => "Integer",
            VarType::Boolean => "Boolean",
            VarType::String => "String",
        }
    }
    fn slot(self) -> usize {
        self as usize
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Causality {
    Parameter,
    CalculatedParameter,
    Input,
    Output,
    Local,
}

impl Causality {
    pub fn xml_name(self) -> &'static str {
        match self {
            Causality::Parameter => "parameter",
            Causality::CalculatedParameter => "calculatedParameter",
            Causality::Input => "input",
            Causality::Output => "output",
            Causality::Local => "local",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Variability {
    Constant,
    Fixed,
    Tunable,
    Discrete,
    Continuous,
}

impl Variability {
    pub fn xml_name(self) -> &'static str {
        match self {
            Variability::Constant => "constant",
            Variability::Fixed => "fixed",
            Variability::Tunable => "tunable",
            Variability::Discrete => "discrete",
            Variability::Continuous => "continuous",
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub enum Start {
    None,
    Real(f64),
    Integer(i32),
    Boolean(bool),
    String(String),
}

/// One `ScalarVariable`.
#[derive(Debug, Clone, PartialEq)]
pub struct Variable {
    pub name: String,
    pub vr: u32,
    pub var_type: VarType,
    pub causality: Causality,
    pub variability: Variability,
    pub start: Start,
    pub unit: Option<&'static str>,
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub description: String,
    /// For outputs: the value references of the inputs they depend on directly (feedthrough).
    pub depends_on: Vec<u32>,
}

impl Variable {
    fn new(
        name: &str,
        vr: u32,
        var_type: VarType,
        causality: Causality,
        variability: Variability,
    ) -> Self {
        Variable {
            name: name.to_owned(),
            vr,
            var_type,
            causality,
            variability,
            start: Start::None,
            unit: None,
            min: None,
            max: None,
            description: String::new(),
            depends_on: Vec::new(),
        }
    }

    pub fn real_input(name: &str, vr: u32, unit: &'static str, start: f64) -> Self {
        let mut v = Self::new(
            name,
            vr,
            VarType::Real,
            Causality::Input,
            Variability::Continuous,
        );
        v.start = Start::Real(start);
        v.unit = Some(unit);
        v
    }

    pub fn real_output(name: &str, vr: u32, unit: &'static str) -> Self {
        let mut v = Self::new(
            name,
            vr,
            VarType::Real,
            Causality::Output,
            Variability::Continuous,
        );
        v.unit = Some(unit);
        v
    }

    /// A fixed real parameter: set before or during initialization, never after.
    pub fn real_parameter(name: &str, vr: u32, unit: &'static str, start: f64) -> Self {
        let mut v = Self::new(
            name,
            vr,
            VarType::Real,
            Causality::Parameter,
            Variability::Fixed,
        );
        v.start = Start::Real(start);
        v.unit = Some(unit);
        v
    }

    pub fn integer_parameter(name: &str, vr: u32, start: i32) -> Self {
        let mut v = Self::new(
            name,
            vr,
            VarType::Integer,
            Causality::Parameter,
            Variability::Fixed,
        );
        v.start = Start::Integer(start);
        v
    }

    pub fn boolean_parameter(name: &str, vr: u32, start: bool) -> Self {
        let mut v = Self::new(
            name,
            vr,
            VarType::Boolean,
            Causality::Parameter,
            Variability::Fixed,
        );
        v.start = Start::Boolean(start);
        v
    }

    pub fn boolean_input(name: &str, vr: u32, start: bool) -> Self {
        let mut v = Self::new(
            name,
            vr,
            VarType::Boolean,
            Causality::Input,
            Variability::Discrete,
        );
        v.start = Start::Boolean(start);
        v
    }

    pub fn string_parameter(name: &str, vr: u32, start: &str) -> Self {
        let mut v = Self::new(
            name,
            vr,
            VarType::String,
            Causality::Parameter,
            Variability::Fixed,
        );
        v.start = Start::String(start.to_owned());
        v
    }

    pub fn describe(mut self, description: &str) -> Self {
        self.description = description.to_owned();
        self
    }
    pub fn min(mut self, min: f64) -> Self {
        self.min = Some(min);
        self
    }
    pub fn max(mut self, max: f64) -> Self {
        self.max = Some(max);
        self
    }
    pub fn tunable(mut self) -> Self {
        self.variability = Variability::Tunable;
        self
    }
    pub fn depends_on(mut self, inputs: &[u32]) -> Self {
        self.depends_on = inputs.to_vec();
        self
    }

    /// May the host set this variable now? `initialized` is true after `fmi2ExitInitializationMode`.
    pub fn settable(&self, initialized: bool) -> Result<(), String> {
        match (self.causality, self.variability) {
            (Causality::Input, _) => Ok(()),
            (Causality::Parameter, Variability::Tunable) => Ok(()),
            (Causality::Parameter, Variability::Fixed) if !initialized => Ok(()),
            (Causality::Parameter, _) => Err(format!(
                "'{}' is a fixed parameter: it can be set only before fmi2ExitInitializationMode",
                self.name
            )),
            (c, _) => Err(format!(
                "'{}' has causality {} and cannot be set",
                self.name,
                c.xml_name()
            )),
        }
    }
}

/// A unit and its SI base-unit exponents (kg, m, s), as `UnitDefinitions` declares it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Unit {
    pub name: &'static str,
    pub kg: i32,
    pub m: i32,
    pub s: i32,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DefaultExperiment {
    pub start_time: f64,
    pub stop_time: f64,
    pub step_size: f64,
}

/// Everything a modelDescription.xml says about a model, and the lookup tables the layer uses.
#[derive(Debug, Clone)]
pub struct ModelInfo {
    pub model_name: String,
    pub model_identifier: String,
    pub description: String,
    pub version: String,
    pub guid: String,
    pub variables: Vec<Variable>,
    pub units: Vec<Unit>,
    pub can_interpolate_inputs: bool,
    pub default_experiment: Option<DefaultExperiment>,
    /// Per type, value reference → index into `variables`. Looked up on every get/set.
    lookup: [VrTable; 4],
    /// Name → index into `variables`: hosts look variables up by name.
    names: HashMap<String, usize>,
}

/// Value reference → index, in pages of [`VR_PAGE`] references allocated where a variable is:
/// two indexings a lookup and no hashing, and a sparse range of references (a shear model's
/// reach past 100,000) costs its few pages, not a table of every reference below the largest.
#[derive(Debug, Clone, Default)]
struct VrTable {
    pages: Vec<Option<Box<[u32; VR_PAGE]>>>,
}

const VR_PAGE: usize = 256;
const NONE: u32 = u32::MAX;

impl VrTable {
    /// False if `vr` is taken.
    fn insert(&mut self, vr: u32, index: u32) -> bool {
        let (page, slot) = (vr as usize / VR_PAGE, vr as usize % VR_PAGE);
        if self.pages.len() <= page {
            self.pages.resize(page + 1, None);
        }
        let entries = self.pages[page].get_or_insert_with(|| Box::new([NONE; VR_PAGE]));
        let free = entries[slot] == NONE;
        if free {
            entries[slot] = index;
        }
        free
    }

    fn get(&self, vr: u32) -> Option<u32> {
        let entries = self.pages.get(vr as usize / VR_PAGE)?.as_ref()?;
        Some(entries[vr as usize % VR_PAGE]).filter(|&i| i != NONE)
    }
}

/// The version of how a [`ModelInfo`] is written as modelDescription.xml, hashed into the GUID:
/// raise it when the writing changes, so that a description written differently gets another
/// GUID.
const DESCRIPTION_FORMAT: &str = "shear-twin fmi2 modelDescription 1";

pub const LOG_CATEGORIES: [(&str, &str); 3] = [
    (
        "logStatusError",
        "errors: wrong call order, bad arguments, a diverging state",
    ),
    ("logStatusWarning", "warnings"),
    ("logCalls", "every fmi2 call, when debug logging is on"),
];

impl ModelInfo {
    /// Check the table (unique names, unique value references per type, a start value where
    /// FMI 2.0 requires one, declared units) and derive the GUID from its content, so any change
    /// to the table changes the GUID.
    pub fn new(
        model_name: &str,
        model_identifier: &str,
        description: &str,
        version: &str,
        variables: Vec<Variable>,
        units: Vec<Unit>,
        can_interpolate_inputs: bool,
        default_experiment: Option<DefaultExperiment>,
    ) -> Result<Self, String> {
        const MAX_DENSE_VR: u32 = 1 << 20;
        let mut lookup: [VrTable; 4] = Default::default();
        let mut names = HashMap::with_capacity(variables.len());
        let inputs: std::collections::HashSet<u32> = variables
            .iter()
            .filter(|v| v.causality == Causality::Input)
            .map(|v| v.vr)
            .collect();
        for (index, v) in variables.iter().enumerate() {
            if names.insert(v.name.clone(), index).is_some() {
                return Err(format!("variable name '{}' appears twice", v.name));
            }
            if v.vr >= MAX_DENSE_VR {
                return Err(format!(
                    "'{}': value reference {} is above {MAX_DENSE_VR}",
                    v.name, v.vr
                ));
            }
            if !lookup[v.var_type.slot()].insert(v.vr, index as u32) {
                return Err(format!(
                    "{} value reference {} appears twice",
                    v.var_type.xml_name(),
                    v.vr
                ));
            }
            let needs_start = matches!(v.causality, Causality::Input | Causality::Parameter);
            if needs_start == matches!(v.start, Start::None) {
                return Err(format!(
                    "'{}': a start value is required for inputs and parameters only",
                    v.name
                ));
            }
            if let Some(unit) = v.unit {
                if !units.iter().any(|u| u.name == unit) {
                    return Err(format!("'{}': unit '{}' is not declared", v.name, unit));
                }
            }
            for dep in &v.depends_on {
                if !inputs.contains(dep) {
                    return Err(format!(
                        "'{}' depends on value reference {dep}, which is no input",
                        v.name
                    ));
                }
            }
        }
        let mut info = ModelInfo {
            model_name: model_name.to_owned(),
            model_identifier: model_identifier.to_owned(),
            description: description.to_owned(),
            version: version.to_owned(),
            guid: String::new(),
            variables,
            units,
            can_interpolate_inputs,
            default_experiment,
            lookup,
            names,
        };
        info.guid = info.fingerprint();
        Ok(info)
    }

    pub fn find(&self, var_type: VarType, vr: u32) -> Option<&Variable> {
        let index = self.lookup[var_type.slot()].get(vr)?;
        Some(&self.variables[index as usize])
    }

    pub fn by_name(&self, name: &str) -> Option<&Variable> {
        self.names.get(name).map(|&i| &self.variables[i])
    }

    /// The complete modelDescription.xml.
    pub fn to_model_description_xml(&self) -> String {
        self.render_xml()
    }

    /// Check that the committed modelDescription at `path` is exactly what this table generates
    /// (and so carries the GUID `fmi2Instantiate` checks). With `UPDATE_MODEL_DESCRIPTION` set in
    /// the environment it is rewritten first: regeneration is on purpose only. For the FMU
    /// crates' tests.
    pub fn check_committed_model_description(&self, path: &std::path::Path) -> Result<(), String> {
        let generated = self.render_xml();
        if std::env::var_os("UPDATE_MODEL_DESCRIPTION").is_some() {
            std::fs::write(path, &generated).map_err(|e| format!("{}: {e}", path.display()))?;
        }
        let committed = std::fs::read_to_string(path).map_err(|e| {
            format!(
                "{}: {e}; regenerate with UPDATE_MODEL_DESCRIPTION=1",
                path.display()
            )
        })?;
        if committed != generated {
            return Err(format!(
                "{} differs from the variable table; regenerate with UPDATE_MODEL_DESCRIPTION=1 and review the diff",
                path.display()
            ));
        }
        if !committed.contains(&format!("guid=\"{}\"", self.guid)) {
            return Err(format!(
                "{} does not carry the GUID the code checks",
                path.display()
            ));
        }
        Ok(())
    }

    /// The GUID: a hash of everything the description is written from (names, references,
    /// types, start values, units, descriptions, dependencies, the default experiment), fed
    /// field by field with lengths, never the rendered XML: a 20-storey shear model's table
    /// is 1,601 variables and 621 kB of XML, rendered for nothing at every instantiation.
    /// [`DESCRIPTION_FORMAT`] changes it when the writing of the description does.
    fn fingerprint(&self) -> String {
        let mut h = Fingerprint::default();
        h.text(DESCRIPTION_FORMAT);
        for text in [
            &self.model_name,
            &self.model_identifier,
            &self.description,
            &self.version,
        ] {
            h.text(text);
        }
        h.number(self.can_interpolate_inputs as u64);
        let experiment = match self.default_experiment {
            Some(d) => [1.0, d.start_time, d.stop_time, d.step_size],
            None => [0.0; 4],
        };
        experiment.into_iter().for_each(|x| h.real(x));
        h.number(self.units.len() as u64);
        for u in &self.units {
            h.text(u.name);
            [u.kg, u.m, u.s]
                .into_iter()
                .for_each(|e| h.number(e as u64));
        }
        h.number(self.variables.len() as u64);
        for v in &self.variables {
            h.text(&v.name);
            h.number(u64::from(v.vr));
            h.text(v.var_type.xml_name());
            h.text(v.causality.xml_name());
            h.text(v.variability.xml_name());
            match &v.start {
                Start::None => h.text("none"),
                Start::Real(x) => {
                    h.text("real");
                    h.real(*x);
                }
                Start::Integer(i) => {
                    h.text("integer");
                    h.number(*i as u64);
                }
                Start::Boolean(b) => {
                    h.text("boolean");
                    h.number(*b as u64);
                }
                Start::String(t) => {
                    h.text("string");
                    h.text(t);
                }
            }
            h.text(v.unit.unwrap_or(""));
            for bound in [v.min, v.max] {
                h.number(bound.is_some() as u64);
                h.real(bound.unwrap_or(0.0));
            }
            h.text(&v.description);
            h.number(v.depends_on.len() as u64);
            v.depends_on.iter().for_each(|d| h.number(u64::from(*d)));
        }
        h.guid()
    }

    fn render_xml(&self) -> String {
        let mut bytes = Vec::new();
        self.write_xml(&mut bytes);
        String::from_utf8(bytes).expect("quick-xml writes UTF-8")
    }

    /// The description, its last line ended, to a sink that cannot fail (memory, a hash).
    fn write_xml(&self, sink: &mut impl std::io::Write) {
        let mut w = Writer::new_with_indent(sink, b' ', 2);
        let ok = "writing XML to memory cannot fail";
        w.write_event(Event::Decl(BytesDecl::new("1.0", Some("UTF-8"), None)))
            .expect(ok);

        let mut root = BytesStart::new("fmiModelDescription");
        root.push_attribute(("fmiVersion", "2.0"));
        root.push_attribute(("modelName", self.model_name.as_str()));
        root.push_attribute(("guid", self.guid.as_str()));
        root.push_attribute(("description", self.description.as_str()));
        root.push_attribute(("author", "shear-twin"));
        root.push_attribute(("version", self.version.as_str()));
        root.push_attribute(("generationTool", "shear-twin fmi2 export layer"));
        root.push_attribute(("variableNamingConvention", "flat"));
        root.push_attribute(("numberOfEventIndicators", "0"));
        w.write_event(Event::Start(root)).expect(ok);

        let mut cs = BytesStart::new("CoSimulation");
        cs.push_attribute(("modelIdentifier", self.model_identifier.as_str()));
        cs.push_attribute(("canHandleVariableCommunicationStepSize", "true"));
        cs.push_attribute((
            "canInterpolateInputs",
            if self.can_interpolate_inputs {
                "true"
            } else {
                "false"
            },
        ));
        cs.push_attribute(("maxOutputDerivativeOrder", "0"));
        cs.push_attribute(("canGetAndSetFMUstate", "true"));
        cs.push_attribute(("canSerializeFMUstate", "true"));
        cs.push_attribute(("canNotUseMemoryManagementFunctions", "true"));
        cs.push_attribute(("providesDirectionalDerivative", "false"));
        w.write_event(Event::Empty(cs)).expect(ok);

        w.write_event(Event::Start(BytesStart::new("UnitDefinitions")))
            .expect(ok);
        for unit in &self.units {
            let mut u = BytesStart::new("Unit");
            u.push_attribute(("name", unit.name));
            w.write_event(Event::Start(u)).expect(ok);
            let mut base = BytesStart::new("BaseUnit");
            for (name, exp) in [("kg", unit.kg), ("m", unit.m), ("s", unit.s)] {
                if exp != 0 {
                    base.push_attribute((name, exp.to_string().as_str()));
                }
            }
            w.write_event(Event::Empty(base)).expect(ok);
            w.write_event(Event::End(BytesEnd::new("Unit"))).expect(ok);
        }
        w.write_event(Event::End(BytesEnd::new("UnitDefinitions")))
            .expect(ok);

        w.write_event(Event::Start(BytesStart::new("LogCategories")))
            .expect(ok);
        for (name, description) in LOG_CATEGORIES {
            let mut c = BytesStart::new("Category");
            c.push_attribute(("name", name));
            c.push_attribute(("description", description));
            w.write_event(Event::Empty(c)).expect(ok);
        }
        w.write_event(Event::End(BytesEnd::new("LogCategories")))
            .expect(ok);

        if let Some(e) = self.default_experiment {
            let mut d = BytesStart::new("DefaultExperiment");
            d.push_attribute(("startTime", fmt_real(e.start_time).as_str()));
            d.push_attribute(("stopTime", fmt_real(e.stop_time).as_str()));
            d.push_attribute(("stepSize", fmt_real(e.step_size).as_str()));
            w.write_event(Event::Empty(d)).expect(ok);
        }

        self.write_variables(&mut w);
        self.write_model_structure(&mut w);
        w.write_event(Event::End(BytesEnd::new("fmiModelDescription")))
            .expect(ok);
        w.into_inner().write_all(b"\n").expect(ok);
    }

    /// `<ModelVariables>`: each variable with its index as a comment.
    fn write_variables<W: std::io::Write>(&self, w: &mut Writer<W>) {
        let ok = "writing XML to memory cannot fail";
        w.write_event(Event::Start(BytesStart::new("ModelVariables")))
            .expect(ok);
        for (index, v) in self.variables.iter().enumerate() {
            w.write_event(Event::Comment(quick_xml::events::BytesText::new(&format!(
                " index {} ",
                index + 1
            ))))
            .expect(ok);
            let mut sv = BytesStart::new("ScalarVariable");
            sv.push_attribute(("name", v.name.as_str()));
            sv.push_attribute(("valueReference", v.vr.to_string().as_str()));
            if !v.description.is_empty() {
                sv.push_attribute(("description", v.description.as_str()));
            }
            sv.push_attribute(("causality", v.causality.xml_name()));
            sv.push_attribute(("variability", v.variability.xml_name()));
            if v.causality == Causality::Parameter {
                sv.push_attribute(("initial", "exact"));
            }
            w.write_event(Event::Start(sv)).expect(ok);
            let mut ty = BytesStart::new(v.var_type.xml_name());
            if let Some(unit) = v.unit {
                ty.push_attribute(("unit", unit));
            }
            let bound = |x: f64| {
                if v.var_type == VarType::Integer {
                    format!("{}", x as i64)
                } else {
                    fmt_real(x)
                }
            };
            if let Some(min) = v.min {
                ty.push_attribute(("min", bound(min).as_str()));
            }
            if let Some(max) = v.max {
                ty.push_attribute(("max", bound(max).as_str()));
            }
            match &v.start {
                Start::None => {}
                Start::Real(x) => ty.push_attribute(("start", fmt_real(*x).as_str())),
                Start::Integer(i) => ty.push_attribute(("start", i.to_string().as_str())),
                Start::Boolean(b) => {
                    ty.push_attribute(("start", if *b { "true" } else { "false" }))
                }
                Start::String(s) => ty.push_attribute(("start", s.as_str())),
            }
            w.write_event(Event::Empty(ty)).expect(ok);
            w.write_event(Event::End(BytesEnd::new("ScalarVariable")))
                .expect(ok);
        }
        w.write_event(Event::End(BytesEnd::new("ModelVariables")))
            .expect(ok);
    }

    /// `<ModelStructure>`: the outputs with their dependencies on inputs, and the initial
    /// unknowns.
    fn write_model_structure<W: std::io::Write>(&self, w: &mut Writer<W>) {
        let ok = "writing XML to memory cannot fail";
        w.write_event(Event::Start(BytesStart::new("ModelStructure")))
            .expect(ok);
        let outputs: Vec<usize> = (0..self.variables.len())
            .filter(|&i| self.variables[i].causality == Causality::Output)
            .collect();
        // Each input's value reference → its index (the first, as FMI counts from 1).
        let mut input_index: HashMap<u32, usize> = HashMap::new();
        for (i, x) in self.variables.iter().enumerate() {
            if x.causality == Causality::Input {
                input_index.entry(x.vr).or_insert(i);
            }
        }
        if !outputs.is_empty() {
            w.write_event(Event::Start(BytesStart::new("Outputs")))
                .expect(ok);
            for &i in &outputs {
                let v = &self.variables[i];
                let mut u = BytesStart::new("Unknown");
                u.push_attribute(("index", (i + 1).to_string().as_str()));
                let deps: Vec<String> = v
                    .depends_on
                    .iter()
                    .filter_map(|vr| input_index.get(vr).copied())
                    .map(|p| (p + 1).to_string())
                    .collect();
                u.push_attribute(("dependencies", deps.join(" ").as_str()));
                let kinds = vec!["dependent"; deps.len()].join(" ");
                u.push_attribute(("dependenciesKind", kinds.as_str()));
                w.write_event(Event::Empty(u)).expect(ok);
            }
            w.write_event(Event::End(BytesEnd::new("Outputs")))
                .expect(ok);
            w.write_event(Event::Start(BytesStart::new("InitialUnknowns")))
                .expect(ok);
            for &i in &outputs {
                let mut u = BytesStart::new("Unknown");
                u.push_attribute(("index", (i + 1).to_string().as_str()));
                w.write_event(Event::Empty(u)).expect(ok);
            }
            w.write_event(Event::End(BytesEnd::new("InitialUnknowns")))
                .expect(ok);
        }
        w.write_event(Event::End(BytesEnd::new("ModelStructure")))
            .expect(ok);
    }
}

/// Shortest text that reads back as the same f64 (Rust's float formatting round-trips).
fn fmt_real(x: f64) -> String {
    let magnitude = x.abs();
    if x == 0.0 || (1e-4..1e15).contains(&magnitude) {
        let text = format!("{x}");
        if text.contains('.') {
            text
        } else {
            format!("{text}.0")
        }
    } else {
        format!("{x:e}")
    }
}

/// A GUID from the content of the description: XXH3's 128-bit hash (the `xxhash-rust` crate),
/// fed as the description is written. Not cryptographic; it only has to change whenever the
/// variable table does. (A byte-at-a-time FNV-1a was 0.18 ms of a 20-storey shear table's
/// 1.14 ms; the table is built at every instantiation and by the host that checks the GUID.)
#[derive(Default)]
struct Fingerprint(xxhash_rust::xxh3::Xxh3Default);

impl Fingerprint {
    fn bytes(&mut self, bytes: &[u8]) {
        self.0.update(bytes);
    }

    /// A text with its length first, so that no two lists of texts feed the same bytes.
    fn text(&mut self, text: &str) {
        self.number(text.len() as u64);
        self.bytes(text.as_bytes());
    }

    fn number(&mut self, x: u64) {
        self.bytes(&x.to_le_bytes());
    }

    fn real(&mut self, x: f64) {
        self.number(x.to_bits());
    }

    fn guid(&self) -> String {
        let hash = self.0.digest128();
        let (a, b) = ((hash >> 64) as u64, hash as u64);
        let mut s = String::with_capacity(38);
        let _ = write!(
            s,
            "{{{:08x}-{:04x}-{:04x}-{:04x}-{:012x}}}",
            a >> 32,
            (a >> 16) & 0xffff,
            a & 0xffff,
            b >> 48,
            b & 0xffff_ffff_ffff
        );
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The value-reference table: references far apart and in one page, a taken one refused,
    /// and nothing found where no variable is (between, beyond, in a page never allocated).
    #[test]
    fn the_reference_table_finds_what_was_put_and_nothing_else() {
        let mut table = VrTable::default();
        for (vr, index) in [(0, 5), (1, 6), (255, 7), (256, 8), (103_192, 9)] {
            assert!(table.insert(vr, index), "{vr}");
        }
        assert!(!table.insert(256, 1), "a reference taken twice");
        for (vr, index) in [(0, 5), (1, 6), (255, 7), (256, 8), (103_192, 9)] {
            assert_eq!(table.get(vr), Some(index), "{vr}");
        }
        for vr in [2, 257, 50_000, 103_191, 103_193, u32::MAX] {
            assert_eq!(table.get(vr), None, "{vr}");
        }
        assert_eq!(table.pages.iter().flatten().count(), 3);
    }

    fn units() -> Vec<Unit> {
        vec![Unit {
            name: "N",
            kg: 1,
            m: 1,
            s: -2,
        }]
    }

    #[test]
    fn guid_changes_with_the_table() {
        let a = ModelInfo::new(
            "m",
            "m",
            "",
            "1",
            vec![Variable::real_input("u", 1, "N", 0.0)],
            units(),
            true,
            None,
        )
        .expect("valid table");
        let b = ModelInfo::new(
            "m",
            "m",
            "",
            "1",
            vec![Variable::real_input("u", 2, "N", 0.0)],
            units(),
            true,
            None,
        )
        .expect("valid table");
        assert_ne!(a.guid, b.guid);
        assert_eq!(a.guid.len(), 38);
    }

    #[test]
    fn duplicate_value_references_are_refused() {
        let err = ModelInfo::new(
            "m",
            "m",
            "",
            "1",
            vec![
                Variable::real_input("u", 1, "N", 0.0),
                Variable::real_output("y", 1, "N"),
            ],
            units(),
            true,
            None,
        )
        .expect_err("duplicate vr");
        assert!(err.contains("appears twice"), "{err}");
    }

    #[test]
    fn parameters_need_start_and_outputs_must_not_have_one() {
        let mut out = Variable::real_output("y", 2, "N");
        out.start = Start::Real(1.0);
        let err = ModelInfo::new("m", "m", "", "1", vec![out], units(), true, None)
            .expect_err("start on output");
        assert!(err.contains("start value"), "{err}");
    }

    #[test]
    fn fixed_parameters_are_settable_only_before_initialization_ends() {
        let p = Variable::real_parameter("k", 3, "N", 1.0);
        assert!(p.settable(false).is_ok());
        assert!(p.settable(true).is_err());
        assert!(Variable::real_output("y", 4, "N").settable(false).is_err());
    }

    #[test]
    fn reals_round_trip_through_the_xml_text() {
        for x in [0.0, 5.2, (-4.605f64).exp(), 4021.0, 1e-9, 0.01953125, 1e300] {
            let back: f64 = fmt_real(x).parse().expect("a number");
            assert_eq!(back, x);
        }
    }
}
