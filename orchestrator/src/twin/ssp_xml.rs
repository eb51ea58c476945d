//! The twin's archive as SSP text: `SystemStructure.ssd` (the system's connectors, each
//! component with its FMU and binding, the connections) and the `.ssv` parameter sets, written
//! with quick-xml.

use std::collections::BTreeMap;

use quick_xml::events::{BytesDecl, BytesEnd, BytesStart, Event};
use quick_xml::Writer;

use super::{Component, ParameterValue, Twin};

const NS_SSD: &str = "http://ssp-standard.org/SSP1/SystemStructureDescription";
const NS_SSC: &str = "http://ssp-standard.org/SSP1/SystemStructureCommon";
const NS_SSV: &str = "http://ssp-standard.org/SSP1/SystemStructureParameterValues";

impl Twin {
    /// `SystemStructure.ssd` of the twin.
    pub(super) fn ssd_xml(&self) -> String {
        let mut w = Writer::new_with_indent(Vec::new(), b' ', 2);
        w.write_event(Event::Decl(BytesDecl::new("1.0", Some("UTF-8"), None)))
            .expect(XML_IN_MEMORY);
        let mut root = BytesStart::new("ssd:SystemStructureDescription");
        root.push_attribute(("xmlns:ssd", NS_SSD));
        root.push_attribute(("xmlns:ssc", NS_SSC));
        root.push_attribute(("xmlns:ssv", NS_SSV));
        root.push_attribute(("version", "1.0"));
        root.push_attribute(("name", self.name.as_str()));
        w.write_event(Event::Start(root)).expect(XML_IN_MEMORY);
        let mut system = BytesStart::new("ssd:System");
        system.push_attribute(("name", self.name.as_str()));
        w.write_event(Event::Start(system)).expect(XML_IN_MEMORY);
        self.write_system_connectors(&mut w);
        w.write_event(Event::Start(BytesStart::new("ssd:Elements")))
            .expect(XML_IN_MEMORY);
        for c in &self.components {
            self.write_component(&mut w, c);
        }
        w.write_event(Event::End(BytesEnd::new("ssd:Elements")))
            .expect(XML_IN_MEMORY);
        self.write_connections(&mut w);
        w.write_event(Event::End(BytesEnd::new("ssd:System")))
            .expect(XML_IN_MEMORY);
        if let Some((start, stop)) = self.default_experiment {
            let mut e = BytesStart::new("ssd:DefaultExperiment");
            e.push_attribute(("startTime", format!("{start:?}").as_str()));
            e.push_attribute(("stopTime", format!("{stop:?}").as_str()));
            w.write_event(Event::Empty(e)).expect(XML_IN_MEMORY);
        }
        w.write_event(Event::End(BytesEnd::new("ssd:SystemStructureDescription")))
            .expect(XML_IN_MEMORY);
        finish_xml(w)
    }

    /// The system's own connectors (its inputs, outputs and parameters) and, with values of
    /// its own, their binding.
    fn write_system_connectors(&self, w: &mut Writer<Vec<u8>>) {
        w.write_event(Event::Start(BytesStart::new("ssd:Connectors")))
            .expect(XML_IN_MEMORY);
        for input in self.system_inputs() {
            write_connector(w, &input, "input", "Real");
        }
        for output in self.system_outputs() {
            write_connector(w, &output, "output", "Real");
        }
        for name in self.system_values().keys() {
            write_connector(w, name, "parameter", "Real");
        }
        if self.has_system_values() {
            for name in self.system_strings().keys() {
                write_connector(w, name, "parameter", "String");
            }
        }
        w.write_event(Event::End(BytesEnd::new("ssd:Connectors")))
            .expect(XML_IN_MEMORY);
        if self.has_system_values() {
            write_binding(w, "resources/twin.ssv");
        }
    }

    /// A component: its FMU, the connectors its connections use and its parameters' binding.
    fn write_component(&self, w: &mut Writer<Vec<u8>>, c: &Component) {
        let mut e = BytesStart::new("ssd:Component");
        e.push_attribute(("name", c.name.as_str()));
        e.push_attribute(("type", "application/x-fmu-sharedlibrary"));
        e.push_attribute(("source", format!("resources/{}", c.fmu_name).as_str()));
        w.write_event(Event::Start(e)).expect(XML_IN_MEMORY);
        w.write_event(Event::Start(BytesStart::new("ssd:Connectors")))
            .expect(XML_IN_MEMORY);
        // Each connector once, however many connections it has (an output can feed
        // another component and the system).
        let mut listed: Vec<(&str, &str)> = Vec::new();
        for conn in &self.connections {
            if conn.end_element.as_deref() == Some(&c.name) {
                listed.push((&conn.end_connector, "input"));
            }
            if conn.start_element.as_deref() == Some(&c.name) {
                listed.push((&conn.start_connector, "output"));
            }
        }
        let mut seen = std::collections::HashSet::new();
        listed.retain(|(name, _)| seen.insert(*name));
        for (name, kind) in listed {
            write_connector(w, name, kind, "Real");
        }
        w.write_event(Event::End(BytesEnd::new("ssd:Connectors")))
            .expect(XML_IN_MEMORY);
        write_binding(w, &format!("resources/{}.ssv", c.name));
        w.write_event(Event::End(BytesEnd::new("ssd:Component")))
            .expect(XML_IN_MEMORY);
    }

    fn write_connections(&self, w: &mut Writer<Vec<u8>>) {
        w.write_event(Event::Start(BytesStart::new("ssd:Connections")))
            .expect(XML_IN_MEMORY);
        for conn in &self.connections {
            let mut e = BytesStart::new("ssd:Connection");
            if let Some(s) = &conn.start_element {
                e.push_attribute(("startElement", s.as_str()));
            }
            e.push_attribute(("startConnector", conn.start_connector.as_str()));
            if let Some(s) = &conn.end_element {
                e.push_attribute(("endElement", s.as_str()));
            }
            e.push_attribute(("endConnector", conn.end_connector.as_str()));
            w.write_event(Event::Empty(e)).expect(XML_IN_MEMORY);
        }
        w.write_event(Event::End(BytesEnd::new("ssd:Connections")))
            .expect(XML_IN_MEMORY);
    }
}

/// Writing XML to a `Vec<u8>` cannot fail; the `expect`s say so.
const XML_IN_MEMORY: &str = "writing XML to memory cannot fail";

fn write_connector(w: &mut Writer<Vec<u8>>, name: &str, kind: &str, ty: &str) {
    let mut c = BytesStart::new("ssd:Connector");
    c.push_attribute(("name", name));
    c.push_attribute(("kind", kind));
    w.write_event(Event::Start(c)).expect(XML_IN_MEMORY);
    w.write_event(Event::Empty(BytesStart::new(format!("ssc:{ty}"))))
        .expect(XML_IN_MEMORY);
    w.write_event(Event::End(BytesEnd::new("ssd:Connector")))
        .expect(XML_IN_MEMORY);
}

fn write_binding(w: &mut Writer<Vec<u8>>, source: &str) {
    w.write_event(Event::Start(BytesStart::new("ssd:ParameterBindings")))
        .expect(XML_IN_MEMORY);
    let mut b = BytesStart::new("ssd:ParameterBinding");
    b.push_attribute(("source", source));
    w.write_event(Event::Empty(b)).expect(XML_IN_MEMORY);
    w.write_event(Event::End(BytesEnd::new("ssd:ParameterBindings")))
        .expect(XML_IN_MEMORY);
}

pub(super) fn ssv_xml(name: &str, parameters: &BTreeMap<String, ParameterValue>) -> String {
    ssv_xml_with_strings(name, parameters, &BTreeMap::new())
}

/// A parameter set with String parameters beside the others.
pub(super) fn ssv_xml_with_strings(
    name: &str,
    parameters: &BTreeMap<String, ParameterValue>,
    strings: &BTreeMap<String, String>,
) -> String {
    let ok = XML_IN_MEMORY;
    let mut w = Writer::new_with_indent(Vec::new(), b' ', 2);
    w.write_event(Event::Decl(BytesDecl::new("1.0", Some("UTF-8"), None)))
        .expect(ok);
    let mut root = BytesStart::new("ssv:ParameterSet");
    root.push_attribute(("xmlns:ssv", NS_SSV));
    root.push_attribute(("version", "1.0"));
    root.push_attribute(("name", name));
    w.write_event(Event::Start(root)).expect(ok);
    w.write_event(Event::Start(BytesStart::new("ssv:Parameters")))
        .expect(ok);
    for (pname, value) in parameters {
        let mut p = BytesStart::new("ssv:Parameter");
        p.push_attribute(("name", pname.as_str()));
        w.write_event(Event::Start(p)).expect(ok);
        let (tag, text) = match value {
            ParameterValue::Real(x) => ("ssv:Real", format!("{x:e}")),
            ParameterValue::Integer(i) => ("ssv:Integer", i.to_string()),
            ParameterValue::Boolean(b) => ("ssv:Boolean", b.to_string()),
        };
        let mut e = BytesStart::new(tag);
        e.push_attribute(("value", text.as_str()));
        w.write_event(Event::Empty(e)).expect(ok);
        w.write_event(Event::End(BytesEnd::new("ssv:Parameter")))
            .expect(ok);
    }
    for (pname, text) in strings {
        let mut p = BytesStart::new("ssv:Parameter");
        p.push_attribute(("name", pname.as_str()));
        w.write_event(Event::Start(p)).expect(ok);
        let mut e = BytesStart::new("ssv:String");
        e.push_attribute(("value", text.as_str()));
        w.write_event(Event::Empty(e)).expect(ok);
        w.write_event(Event::End(BytesEnd::new("ssv:Parameter")))
            .expect(ok);
    }
    w.write_event(Event::End(BytesEnd::new("ssv:Parameters")))
        .expect(ok);
    w.write_event(Event::End(BytesEnd::new("ssv:ParameterSet")))
        .expect(ok);
    finish_xml(w)
}

/// The written document as text, ending with a newline.
fn finish_xml(w: Writer<Vec<u8>>) -> String {
    let mut s = String::from_utf8(w.into_inner()).expect("quick-xml writes UTF-8");
    s.push('\n');
    s
}
