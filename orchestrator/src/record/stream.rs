//! A record one CSV line at a time, as a live stream gives it (`twin watch`): the header line
//! gives the columns as a file's header does (the same reading: names, units, `--columns`
//! maps), each later line one sample.

use ::structure::channel::Channel;

use super::read::{parse_value, Layout};
use super::ColumnMap;

/// The header a stream without one (an MQTT message) is taken to have: `time`, the excitation
/// (`force` or `ground_acc`) and `acc1..accN`; the rig's [`::structure::paper::header`] for
/// the paper's rig.
pub fn default_header(excitation: Channel, storeys: usize) -> String {
    let mut header = format!("time,{}", excitation.name());
    for floor in 1..=storeys {
        header.push_str(&format!(",acc{floor}"));
    }
    header
}

/// What one field of a line is: its place among the samples' values and its factor to SI.
#[derive(Debug, Clone, Copy)]
enum Role {
    Time(f64),
    Excitation(f64),
    /// The response's place in [`LineLayout::responses`].
    Response(usize, f64),
    /// A column kept by name in a file (`control`): not part of a stream's sample.
    Other,
}

/// A stream's header line read as a record's header is: which field is the time, the
/// excitation and each response channel, and each one's factor to SI (a header field may carry
/// its unit, `acc1 (g)`).
#[derive(Debug, Clone)]
pub struct LineLayout {
    roles: Vec<Role>,
    /// Each field's name, for messages.
    names: Vec<String>,
    excitation: Channel,
    responses: Vec<Channel>,
}

impl LineLayout {
    /// The layout of a header line with the twin's own column names.
    pub fn parse(line: &str) -> Result<Self, String> {
        Self::parse_with(line, &ColumnMap::default())
    }

    /// The layout of a header line, its names mapped through `map` (`--columns`); Err says
    /// which column is not one the twin knows, has a unit that is not its quantity's, appears
    /// twice, or which is missing (the time, the excitation, a response).
    pub fn parse_with(line: &str, map: &ColumnMap) -> Result<Self, String> {
        let header: Vec<String> = line.split(',').map(|f| f.trim().to_owned()).collect();
        let layout = Layout::parse(&header, map)?;
        let time = layout.time.ok_or_else(|| {
            format!("'{line}' has no column 'time' (a stream's samples are timed)")
        })?;
        let mut roles = vec![Role::Other; header.len()];
        let mut names: Vec<String> = header.clone();
        let time_unit = ::structure::channel::parse_header_field(&map.apply(&header[time]))
            .map(|(_, unit)| unit.to_si())
            .unwrap_or(1.0);
        roles[time] = Role::Time(time_unit);
        names[time] = "time".to_owned();
        let (i, excitation, unit) = layout
            .excitation
            .ok_or_else(|| format!("'{line}' has no excitation column"))?;
        roles[i] = Role::Excitation(unit.to_si());
        names[i] = excitation.name();
        let mut responses = Vec::with_capacity(layout.responses.len());
        for (slot, &(i, channel, unit)) in layout.responses.iter().enumerate() {
            roles[i] = Role::Response(slot, unit.to_si());
            names[i] = channel.name();
            responses.push(channel);
        }
        Ok(LineLayout {
            roles,
            names,
            excitation,
            responses,
        })
    }

    /// The excitation the stream measures (`force` or `ground_acc`).
    pub fn excitation(&self) -> Channel {
        self.excitation
    }

    /// The response channels, in the order [`LineLayout::sample_into`] gives them.
    pub fn responses(&self) -> &[Channel] {
        &self.responses
    }

    /// The same columns with the responses given in the order of `channels` (the same set);
    /// Err names what differs.
    pub fn in_order(mut self, channels: &[Channel]) -> Result<Self, String> {
        let names = |c: &[Channel]| c.iter().map(Channel::name).collect::<Vec<_>>().join(",");
        let mut sorted_here = self.responses.clone();
        let mut sorted_there = channels.to_vec();
        sorted_here.sort_by_key(Channel::name);
        sorted_there.sort_by_key(Channel::name);
        if sorted_here != sorted_there {
            return Err(format!(
                "the header's channels ({}) are not the stream's ({})",
                names(&self.responses),
                names(channels)
            ));
        }
        for role in &mut self.roles {
            if let Role::Response(slot, factor) = *role {
                let channel = self.responses[slot];
                let to = channels.iter().position(|c| *c == channel).unwrap_or(slot);
                *role = Role::Response(to, factor);
            }
        }
        self.responses = channels.to_vec();
        Ok(self)
    }

    /// One line's (time, excitation) in SI, its responses (SI) into `responses` (as many as
    /// [`LineLayout::responses`]); Err says why the line is not a sample.
    pub fn sample_into(&self, line: &str, responses: &mut [f64]) -> Result<(f64, f64), String> {
        let width = line.bytes().filter(|&b| b == b',').count() + 1;
        if width != self.roles.len() {
            return Err(format!(
                "{width} fields, the header has {}",
                self.roles.len()
            ));
        }
        let (mut time, mut excitation) = (f64::NAN, f64::NAN);
        let si = |v: f64, factor: f64| if factor == 1.0 { v } else { v * factor };
        for ((field, role), name) in line.split(',').zip(&self.roles).zip(&self.names) {
            match *role {
                Role::Time(f) => time = si(parse_value(name, field.trim())?, f),
                Role::Excitation(f) => excitation = si(parse_value(name, field.trim())?, f),
                Role::Response(slot, f) => {
                    responses[slot] = si(parse_value(name, field.trim())?, f);
                }
                Role::Other => {}
            }
        }
        Ok((time, excitation))
    }
}

/// The sampling interval from one step of printed times: the coarsest round rate (1, 0.1,
/// 0.01 or 0.001 Hz) whose interval is within the times' 1 µs printing of it, else the step.
pub fn nominal_step(step: f64) -> f64 {
    for resolution in [1.0, 0.1, 0.01, 0.001] {
        let rate = (1.0 / step / resolution).round() * resolution;
        if rate > 0.0 && (1.0 / rate - step).abs() <= 2e-6 {
            return 1.0 / rate;
        }
    }
    step
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stream_header_with_units_gives_samples_in_si() {
        let layout =
            LineLayout::parse("acc3,time,force (kN),acc1 (g),acc2 (mm/s2)").expect("layout");
        let names: Vec<String> = layout.responses().iter().map(Channel::name).collect();
        assert_eq!(names, ["acc3", "acc1", "acc2"]);
        let mut acc = [0.0; 3];
        let (t, f) = layout
            .sample_into("3, 0.5, 2, 1, 1000", &mut acc)
            .expect("sample");
        assert_eq!((t, f), (0.5, 2000.0));
        assert_eq!(acc, [3.0, 9.80665, 1.0]);
        let ordered = layout
            .in_order(&["acc1", "acc2", "acc3"].map(|n| Channel::parse(n).expect("name")))
            .expect("the same channels");
        ordered
            .sample_into("3, 0.5, 2, 1, 1000", &mut acc)
            .expect("sample");
        assert_eq!(acc, [9.80665, 1.0, 3.0]);
        let e = LineLayout::parse("time,acc1,acc2").expect_err("no excitation");
        assert!(e.contains("'force' or 'ground_acc'"), "{e}");
        let e = LineLayout::parse("time,force,acc1 (mm/s),acc2,acc3").expect_err("wrong unit");
        assert!(e.contains("acc1 (mm/s)"), "{e}");
        let e = LineLayout::parse("time,force,acc1,note").expect_err("unknown column");
        assert!(e.contains("'note'"), "{e}");
        let e = LineLayout::parse("force,acc1").expect_err("no time");
        assert!(e.contains("'time'"), "{e}");
        let e = layout_err("time,force,acc1", "1,2", 1);
        assert!(e.contains("2 fields, the header has 3"), "{e}");
    }

    fn layout_err(header: &str, line: &str, n: usize) -> String {
        let layout = LineLayout::parse(header).expect("layout");
        let mut out = vec![0.0; n];
        layout.sample_into(line, &mut out).expect_err("refused")
    }

    #[test]
    fn ground_motion_velocities_and_a_column_map() {
        let map = ColumnMap::new(
            [("ag".to_owned(), "ground_acc (g)".to_owned())]
                .into_iter()
                .collect(),
        )
        .expect("map");
        let layout = LineLayout::parse_with("time,ag,vel2 (mm/s),acc5", &map).expect("layout");
        assert_eq!(layout.excitation().name(), "ground_acc");
        let mut out = [0.0; 2];
        let (t, ag) = layout
            .sample_into("0.01,0.5,20,3", &mut out)
            .expect("sample");
        assert_eq!((t, ag), (0.01, 0.5 * 9.80665));
        assert_eq!(out, [0.02, 3.0]);
        assert_eq!(
            default_header(Channel::parse("ground_acc").expect("g"), 2),
            "time,ground_acc,acc1,acc2"
        );
        let rig = ::structure::paper::structure();
        let force = Channel::Excitation(::structure::channel::ExcitationKind::of(&rig.excitation));
        assert_eq!(
            default_header(force, rig.storeys()),
            ::structure::paper::header()
        );
    }
}
