//! SSP 1.0 system structure files: the parts of `SystemStructure.ssd` and of `.ssv` parameter
//! sets a co-simulation master uses — the system's connectors and default experiment, its
//! components (FMUs in the archive) with their connectors and parameter bindings, and the
//! connections. Namespace prefixes are ignored (local names); nested systems are refused.

use std::borrow::Cow;

use quick_xml::events::{BytesStart, Event};

/// A connection between system connectors (`element` None) and component connectors.
#[derive(Debug, Clone, PartialEq)]
pub struct Connection {
    pub start_element: Option<String>,
    pub start_connector: String,
    pub end_element: Option<String>,
    pub end_connector: String,
}

/// A connector of the system or of a component.
#[derive(Debug, Clone, PartialEq)]
pub struct Connector {
    pub name: String,
    /// `input`, `output`, `parameter`, `calculatedParameter`, …
    pub kind: String,
    /// `Real`, `Integer`, `Boolean`, `String`, `Enumeration`, or None when not given.
    pub type_name: Option<String>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct SsdComponent {
    pub name: String,
    /// The FMU's path inside the archive (`resources/x.fmu`).
    pub source: String,
    pub connectors: Vec<Connector>,
    /// `.ssv` files bound to the component, paths inside the archive.
    pub bindings: Vec<String>,
}

/// What a master needs of `SystemStructure.ssd`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Ssd {
    pub name: String,
    pub start_time: Option<f64>,
    pub stop_time: Option<f64>,
    pub connectors: Vec<Connector>,
    pub components: Vec<SsdComponent>,
    pub connections: Vec<Connection>,
    /// `.ssv` files bound to the system itself.
    pub system_bindings: Vec<String>,
}

/// A value of an `.ssv` parameter set.
#[derive(Debug, Clone, PartialEq)]
pub enum SsvValue {
    Real(f64),
    Integer(i32),
    Boolean(bool),
    String(String),
    /// An enumeration item, by name.
    Enumeration(String),
}

/// An element's attributes by local name, borrowed from the document where no entity is
/// escaped (a twin's 20-storey parameter set has some 1,900 elements: one map and two strings
/// an attribute were a tenth of reading the twin).
struct Attributes<'e>(Vec<(&'e [u8], Cow<'e, str>)>);

impl Attributes<'_> {
    fn get(&self, key: &str) -> Option<&str> {
        self.0
            .iter()
            .find(|(k, _)| *k == key.as_bytes())
            .map(|(_, v)| v.as_ref())
    }

    fn owned(&self, key: &str) -> Option<String> {
        self.get(key).map(str::to_owned)
    }
}

/// An element's attributes (without quick-xml's check for a repeated name, which allocates for
/// every element: a 20-storey twin's files have 5,500 of them; the first of a repeated name is
/// the one read).
fn attributes<'e>(e: &'e BytesStart) -> Result<Attributes<'e>, String> {
    e.attributes()
        .with_checks(false)
        .map(|attr| {
            let attr = attr.map_err(|e| e.to_string())?;
            let value = attr.unescape_value().map_err(|e| e.to_string())?;
            Ok((attr.key.local_name().into_inner(), value))
        })
        .collect::<Result<_, String>>()
        .map(Attributes)
}

const TYPES: [&str; 5] = ["Real", "Integer", "Boolean", "String", "Enumeration"];

fn parse_time(attrs: &Attributes, key: &str) -> Result<Option<f64>, String> {
    attrs
        .get(key)
        .map(|text| {
            text.trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("DefaultExperiment {key} '{text}' is not a number"))
        })
        .transpose()
}

/// Parse `SystemStructure.ssd`.
pub fn parse_ssd(xml: &str) -> Result<Ssd, String> {
    let mut reader = quick_xml::Reader::from_str(xml);
    let mut ssd = SsdReader::default();
    loop {
        let event = reader
            .read_event()
            .map_err(|e| format!("malformed XML at byte {}: {e}", reader.error_position()))?;
        match &event {
            Event::Start(e) | Event::Empty(e) => {
                let name = e.local_name();
                let local = String::from_utf8_lossy(name.as_ref());
                let attrs = attributes(e)?;
                ssd.element(&local, &attrs, matches!(event, Event::Start(_)))?;
            }
            Event::End(e) => ssd.end(e.local_name().as_ref()),
            Event::Eof => break,
            _ => {}
        }
    }
    if !ssd.saw_root {
        return Err("no SystemStructureDescription element".into());
    }
    Ok(ssd.parsed)
}

/// `SystemStructure.ssd` as it is read: what is parsed so far and where the reader is.
#[derive(Default)]
struct SsdReader {
    parsed: Ssd,
    in_component: bool,
    depth_system: usize,
    saw_root: bool,
    /// The connector whose type element comes next.
    open_connector: Option<Connector>,
}

impl SsdReader {
    /// An element opened (`is_start`) or empty, by its local name.
    fn element(&mut self, local: &str, attrs: &Attributes, is_start: bool) -> Result<(), String> {
        match local {
            "SystemStructureDescription" => {
                self.saw_root = true;
                if attrs.get("version") != Some("1.0") {
                    return Err(format!(
                        "version is {:?}; SSP 1.0 is expected",
                        attrs.get("version")
                    ));
                }
                self.parsed.name = attrs.owned("name").unwrap_or_default();
            }
            "System" => {
                self.depth_system += 1;
                if self.depth_system > 1 {
                    return Err("nested systems are not supported".into());
                }
            }
            "DefaultExperiment" => {
                self.parsed.start_time = parse_time(&attrs, "startTime")?;
                self.parsed.stop_time = parse_time(&attrs, "stopTime")?;
            }
            "Component" => {
                let name = attrs.owned("name").ok_or("a Component has no name")?;
                let source = attrs
                    .owned("source")
                    .ok_or_else(|| format!("component '{name}' has no source"))?;
                self.parsed.components.push(SsdComponent {
                    name,
                    source,
                    connectors: Vec::new(),
                    bindings: Vec::new(),
                });
                self.in_component = is_start;
            }
            "Connector" => {
                let name = attrs.owned("name").ok_or("a Connector has no name")?;
                let connector = Connector {
                    name,
                    kind: attrs.owned("kind").unwrap_or_default(),
                    type_name: None,
                };
                if is_start {
                    self.open_connector = Some(connector);
                } else {
                    push_connector(&mut self.parsed, self.in_component, connector);
                }
            }
            t if TYPES.contains(&t) => {
                if let Some(c) = self.open_connector.as_mut() {
                    c.type_name = Some(t.to_owned());
                }
            }
            "ParameterBinding" => {
                let source = attrs
                    .owned("source")
                    .ok_or("a ParameterBinding has no source (inline values are not supported)")?;
                match (self.in_component, self.parsed.components.last_mut()) {
                    (true, Some(c)) => c.bindings.push(source),
                    _ => self.parsed.system_bindings.push(source),
                }
            }
            "Connection" => {
                let get = |k: &str| attrs.owned(k);
                self.parsed.connections.push(Connection {
                    start_element: get("startElement"),
                    start_connector: get("startConnector")
                        .ok_or("a Connection has no startConnector")?,
                    end_element: get("endElement"),
                    end_connector: get("endConnector").ok_or("a Connection has no endConnector")?,
                });
            }
            _ => {}
        }
        Ok(())
    }

    fn end(&mut self, local: &[u8]) {
        match local {
            b"Component" => self.in_component = false,
            b"Connector" => {
                if let Some(c) = self.open_connector.take() {
                    push_connector(&mut self.parsed, self.in_component, c);
                }
            }
            _ => {}
        }
    }
}

fn push_connector(parsed: &mut Ssd, in_component: bool, connector: Connector) {
    match (in_component, parsed.components.last_mut()) {
        (true, Some(c)) => c.connectors.push(connector),
        _ => parsed.connectors.push(connector),
    }
}

/// Parse an `.ssv` parameter set: (name, value) in file order.
pub fn parse_ssv(xml: &str) -> Result<Vec<(String, SsvValue)>, String> {
    let mut reader = quick_xml::Reader::from_str(xml);
    let mut out = Vec::new();
    let mut current: Option<String> = None;
    loop {
        let event = reader
            .read_event()
            .map_err(|e| format!("malformed XML at byte {}: {e}", reader.error_position()))?;
        match &event {
            Event::Start(e) | Event::Empty(e) => {
                let name = e.local_name();
                let local = String::from_utf8_lossy(name.as_ref());
                let attrs = attributes(e)?;
                match local.as_ref() {
                    "Parameter" => {
                        current = Some(attrs.owned("name").ok_or("a Parameter has no name")?)
                    }
                    t if TYPES.contains(&t) && current.is_some() => {
                        let name = current.take().unwrap_or_default();
                        let text = attrs
                            .get("value")
                            .ok_or_else(|| format!("parameter '{name}' has no value"))?;
                        let bad = || format!("parameter '{name}': '{text}' is not a valid {local}");
                        let value = match t {
                            "Real" => SsvValue::Real(
                                text.trim()
                                    .parse::<f64>()
                                    .ok()
                                    .filter(|x| x.is_finite())
                                    .ok_or_else(bad)?,
                            ),
                            "Integer" => SsvValue::Integer(text.trim().parse().map_err(|_| bad())?),
                            "Boolean" => SsvValue::Boolean(match text.trim() {
                                "true" | "1" => true,
                                "false" | "0" => false,
                                _ => return Err(bad()),
                            }),
                            "String" => SsvValue::String(text.to_owned()),
                            _ => SsvValue::Enumeration(text.to_owned()),
                        };
                        out.push((name, value));
                    }
                    _ => {}
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ssd_connectors_experiment_and_bindings_are_read() {
        let xml = r#"<?xml version="1.0"?>
<ssd:SystemStructureDescription xmlns:ssd="a" xmlns:ssc="b" version="1.0" name="sys">
  <ssd:System name="sys">
    <ssd:Connectors>
      <ssd:Connector name="u" kind="input"><ssc:Real/></ssd:Connector>
      <ssd:Connector name="n" kind="output"><ssc:Integer/></ssd:Connector>
    </ssd:Connectors>
    <ssd:Elements>
      <ssd:Component name="a" source="resources/a.fmu">
        <ssd:Connectors><ssd:Connector name="x" kind="output"><ssc:Real/></ssd:Connector></ssd:Connectors>
        <ssd:ParameterBindings><ssd:ParameterBinding source="resources/a.ssv"/></ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
    <ssd:Connections><ssd:Connection startElement="a" startConnector="x" endConnector="n"/></ssd:Connections>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0.5" stopTime="2"/>
</ssd:SystemStructureDescription>"#;
        let ssd = parse_ssd(xml).expect("parses");
        assert_eq!(ssd.name, "sys");
        assert_eq!((ssd.start_time, ssd.stop_time), (Some(0.5), Some(2.0)));
        assert_eq!(ssd.connectors.len(), 2);
        assert_eq!(ssd.connectors[1].type_name.as_deref(), Some("Integer"));
        assert_eq!(ssd.components[0].connectors[0].name, "x");
        assert_eq!(ssd.components[0].bindings, vec!["resources/a.ssv"]);
        assert_eq!(ssd.connections[0].end_element, None);
    }

    #[test]
    fn ssv_reads_every_type_and_refuses_bad_values() {
        let xml = r#"<ssv:ParameterSet xmlns:ssv="x" version="1.0" name="p"><ssv:Parameters>
            <ssv:Parameter name="r"><ssv:Real value="1.5"/></ssv:Parameter>
            <ssv:Parameter name="i"><ssv:Integer value="-3"/></ssv:Parameter>
            <ssv:Parameter name="b"><ssv:Boolean value="true"/></ssv:Parameter>
            <ssv:Parameter name="s"><ssv:String value="a b"/></ssv:Parameter>
            <ssv:Parameter name="e"><ssv:Enumeration value="High"/></ssv:Parameter>
            </ssv:Parameters></ssv:ParameterSet>"#;
        let values = parse_ssv(xml).expect("parses");
        assert_eq!(
            values,
            vec![
                ("r".into(), SsvValue::Real(1.5)),
                ("i".into(), SsvValue::Integer(-3)),
                ("b".into(), SsvValue::Boolean(true)),
                ("s".into(), SsvValue::String("a b".into())),
                ("e".into(), SsvValue::Enumeration("High".into())),
            ]
        );
        let bad = r#"<ssv:ParameterSet xmlns:ssv="x" version="1.0" name="p"><ssv:Parameters>
            <ssv:Parameter name="k1"><ssv:Real value="abc"/></ssv:Parameter></ssv:Parameters></ssv:ParameterSet>"#;
        assert!(parse_ssv(bad).expect_err("bad real").contains("k1"));
    }

    #[test]
    fn ssd_refuses_other_versions_nesting_and_garbage() {
        assert!(parse_ssd("<ssd:SystemStructureDescription version=\"2.0\" name=\"x\"/>").is_err());
        assert!(parse_ssd("<nothing/>").is_err());
        assert!(parse_ssd("<a><b></a>").is_err());
        let nested = r#"<SystemStructureDescription version="1.0" name="x"><System name="a"><Elements><System name="b"/></Elements></System></SystemStructureDescription>"#;
        assert!(parse_ssd(nested).expect_err("nested").contains("nested"));
    }
}
