//! The LQR FMU's variable table, per controller layout (the structure's storeys and excitation,
//! the actuator's floor, the channels measured). Value-reference constants carry the XML names.
//!
//! FMI 2.0 fixes the variables in modelDescription.xml, so each layout has its own table and
//! GUID, and one library serves them all: the layout is read from `resources/structure.json` at
//! `fmi2Instantiate` ([`Layout`]); without it, the paper's rig (three storeys, the shaker and the
//! actuator on floor 1, an accelerometer on each floor).

use std::sync::{Mutex, OnceLock};

use fmi2::{DefaultExperiment, ModelInfo, Unit, Variability, Variable};
use serde::{Deserialize, Serialize};
use structure::channel::{Channel, Quantity};
use structure::{Excitation, Structure, MAX_STOREYS};

/// The floor the control force acts on by default: the paper rig's.
pub const DEFAULT_ACTUATOR_FLOOR: usize = structure::paper::CONTROL_FLOOR;

/// Inputs: the excitation (`force`, N, or `ground_acc`, m/s²); output `control_force`.
pub const FORCE: u32 = 1;
pub const CONTROL_FORCE: u32 = 2;
pub const GROUND_ACC: u32 = 3;
pub const STATE_SCALE: u32 = 10;
/// Integer: 0 integrate, 1 Kalman.
pub const ESTIMATOR: u32 = 11;
pub const HIGHPASS_HZ: u32 = 12;
pub const PROCESS_SD: u32 = 13;
pub const SAMPLE_INTERVAL: u32 = 14;
/// Per-state, per-floor and per-storey quantities in blocks of [`BLOCK`] references:
/// `gain{i}` is `GAIN + i − 1` (the state `[y1..yN, ẏ1..ẏN]`, 2N ≤ 2·[`MAX_STOREYS`]), `m{i}`
/// `MASS + i − 1`, and the measured inputs `acc{i}`, `vel{i}`, `disp{i}` likewise.
pub const BLOCK: u32 = 100;
pub const GAIN: u32 = 1000;
pub const MASS: u32 = GAIN + BLOCK;
pub const DAMPING: u32 = MASS + BLOCK;
pub const STIFFNESS: u32 = DAMPING + BLOCK;
pub const ACC: u32 = STIFFNESS + BLOCK;
pub const VEL: u32 = ACC + BLOCK;
pub const DISP: u32 = VEL + BLOCK;
/// `sensor_sd{j}`: the noise sd of the j-th measured channel (in the table's order of the
/// measured inputs), `SENSOR_SD + j − 1`; up to 3·[`MAX_STOREYS`] channels.
pub const SENSOR_SD: u32 = 2000;

const _: () = assert!(2 * MAX_STOREYS as u32 <= BLOCK);
const _: () = assert!(SENSOR_SD >= DISP + BLOCK);

pub const MODEL_IDENTIFIER: &str = "fmu_lqr";

/// The shear FMU's defaults (the reference paper's prior means), checked against it by a test.
pub const DEFAULT_MASS: f64 = structure::paper::MASS;
pub const DEFAULT_DAMPING: f64 = 0.010_001_702_004_705_479; // exp(−4.605)
pub const DEFAULT_STIFFNESS: f64 = structure::paper::STIFFNESS;
pub const DEFAULT_HIGHPASS_HZ: f64 = 0.5;
pub const DEFAULT_PROCESS_SD: f64 = 0.1;
pub const DEFAULT_SENSOR_SD: f64 = 0.01;
pub const DEFAULT_SAMPLE_INTERVAL: f64 = 1.0 / 51.2;

/// What `resources/structure.json` holds: the structure the observer models (`mass`, `damping`,
/// `stiffness`, `excitation`: the start values of m, c, k), the actuator's floor (1 when absent)
/// and the channels the controller reads (`["acc1", "vel3"]`; every floor's acceleration when
/// absent).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Layout {
    #[serde(flatten)]
    pub structure: Structure,
    #[serde(default = "first_floor")]
    pub actuator_floor: usize,
    #[serde(default, with = "channel_names")]
    pub measured: Vec<Channel>,
}

fn first_floor() -> usize {
    DEFAULT_ACTUATOR_FLOOR
}

/// The channels as their names (`acc1`), in JSON.
mod channel_names {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};
    use structure::channel::Channel;

    pub fn serialize<S: Serializer>(c: &[Channel], s: S) -> Result<S::Ok, S::Error> {
        c.iter().map(Channel::name).collect::<Vec<_>>().serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Channel>, D::Error> {
        Vec::<String>::deserialize(d)?
            .iter()
            .map(|n| {
                Channel::parse(n).ok_or_else(|| {
                    serde::de::Error::custom(format!(
                        "measured channel '{n}' is not acc<i>, vel<i> or disp<i>"
                    ))
                })
            })
            .collect()
    }
}

impl Default for Layout {
    /// The paper's rig at its prior means: three storeys, the shaker and the actuator on floor
    /// 1, acc1..acc3 measured.
    fn default() -> Self {
        Layout {
            structure: structure::paper::structure(),
            actuator_floor: DEFAULT_ACTUATOR_FLOOR,
            measured: structure::paper::channels(),
        }
    }
}

/// `acc1..accN`.
pub fn every_acceleration(storeys: usize) -> Vec<Channel> {
    (1..=storeys)
        .map(|floor| Channel::Response {
            quantity: Quantity::Acceleration,
            floor,
        })
        .collect()
}

/// A measured channel's input value reference.
pub fn input_vr(channel: &Channel) -> Option<u32> {
    match *channel {
        Channel::Response { quantity, floor } if (1..=MAX_STOREYS).contains(&floor) => {
            let base = match quantity {
                Quantity::Acceleration => ACC,
                Quantity::Velocity => VEL,
                Quantity::Displacement => DISP,
                _ => return None,
            };
            Some(base + floor as u32 - 1)
        }
        _ => None,
    }
}

impl Layout {
    pub fn storeys(&self) -> usize {
        self.structure.storeys()
    }

    /// Checked: a valid structure, an actuator on a floor it has, one to three channels per
    /// floor it has (each once), every floor's acceleration when none are named. The
    /// measured channels come out in the controller's order: accelerations, velocities,
    /// displacements, each by floor.
    pub fn checked(mut self) -> Result<Layout, String> {
        self.structure.validate().map_err(|e| e.to_string())?;
        let n = self.storeys();
        if !(1..=n).contains(&self.actuator_floor) {
            return Err(format!(
                "actuator_floor = {}: the structure has floors 1 to {n}",
                self.actuator_floor
            ));
        }
        if self.measured.is_empty() {
            self.measured = every_acceleration(n);
        }
        for c in &self.measured {
            c.check(&c.name(), &self.structure)
                .map_err(|e| format!("measured: {e}"))?;
            if input_vr(c).is_none() {
                return Err(format!(
                    "measured: '{}' is not acc<i>, vel<i> or disp<i>",
                    c.name()
                ));
            }
        }
        let rank = |c: &Channel| match c {
            Channel::Response { quantity, floor } => (
                match quantity {
                    Quantity::Acceleration => 0,
                    Quantity::Velocity => 1,
                    _ => 2,
                },
                *floor,
            ),
            _ => (3, 0),
        };
        self.measured.sort_by_key(rank);
        let before = self.measured.len();
        self.measured.dedup();
        if self.measured.len() != before {
            return Err("measured: a channel is named twice".into());
        }
        Ok(self)
    }

    /// The paper's rig (its table is [`info`]): the default layout.
    pub fn is_paper(&self) -> bool {
        *self == Layout::default()
    }
}

fn units() -> Vec<Unit> {
    let unit = |name, kg, m, s| Unit { name, kg, m, s };
    vec![
        unit("s", 0, 0, 1),
        unit("Hz", 0, 0, -1),
        unit("kg", 1, 0, 0),
        unit("m", 0, 1, 0),
        unit("m/s", 0, 1, -1),
        unit("m/s2", 0, 1, -2),
        unit("N", 1, 1, -2),
        unit("N.s/m", 1, 0, -1),
        unit("N/m", 1, 0, -2),
    ]
}

fn unit_of(q: Quantity) -> &'static str {
    match q {
        Quantity::Acceleration => "m/s2",
        Quantity::Velocity => "m/s",
        _ => "m",
    }
}

fn describe_channel(c: &Channel, excitation: &Excitation) -> String {
    let Channel::Response { quantity, floor } = *c else {
        return c.name();
    };
    match quantity {
        Quantity::Acceleration => match excitation {
            Excitation::Base => format!(
                "measured absolute acceleration of floor {floor} (relative plus ground_acc)"
            ),
            Excitation::Force { .. } => format!("measured absolute acceleration of floor {floor}"),
        },
        Quantity::Velocity => format!("measured velocity of floor {floor} relative to the ground"),
        _ => format!("measured displacement of floor {floor} relative to the ground"),
    }
}

fn variables(layout: &Layout) -> Vec<Variable> {
    let mut v = measured_inputs(layout);
    v.push(excitation_input(&layout.structure.excitation));
    v.push(control_force_output(layout.actuator_floor));
    v.extend(gains(layout.storeys()));
    v.extend(observer_model(&layout.structure));
    v.extend(estimator_parameters(layout));
    v
}

/// The measured channels, inputs sampled at `fmi2DoStep`.
fn measured_inputs(layout: &Layout) -> Vec<Variable> {
    let mut v = Vec::new();
    for c in &layout.measured {
        let Channel::Response { quantity, .. } = *c else {
            continue;
        };
        let vr = input_vr(c).expect("a checked layout's channels have inputs");
        v.push(
            Variable::real_input(&c.name(), vr, unit_of(quantity), 0.0).describe(&format!(
                "{}, sampled at fmi2DoStep",
                describe_channel(c, &layout.structure.excitation)
            )),
        );
    }
    v
}

/// The excitation now: the Kalman observer's known input.
fn excitation_input(excitation: &Excitation) -> Variable {
    match excitation {
        Excitation::Force { floor } => Variable::real_input("force", FORCE, "N", 0.0).describe(
            &format!("excitation force on floor {floor} now (the Kalman observer's known input)"),
        ),
        Excitation::Base => Variable::real_input("ground_acc", GROUND_ACC, "m/s2", 0.0)
            .describe("ground acceleration at the base now (the Kalman observer's known input)"),
    }
}

fn control_force_output(actuator_floor: usize) -> Variable {
    let mut out = Variable::real_output("control_force", CONTROL_FORCE, "N").describe(&format!(
        "the command on floor {actuator_floor} computed at the last fmi2DoStep from the sample at its start; it acts on the structure over the next step"
    ));
    // Changes only at fmi2DoStep: no direct feedthrough from the inputs.
    out.variability = Variability::Discrete;
    out
}

/// `gain{i}` per state and `state_scale`.
fn gains(n: usize) -> Vec<Variable> {
    let mut v = Vec::new();
    for i in 0..2 * n {
        let state = if i < n {
            format!("y{}", i + 1)
        } else {
            format!("v{}", i - n + 1)
        };
        let mut g = Variable::real_parameter(&format!("gain{}", i + 1), GAIN + i as u32, "N", 0.0)
            .describe(&format!(
                "LQR gain on state {state} (N per state unit; f_c = sum gain_i w_i)"
            ));
        // N per state unit: the unit depends on state_scale.
        g.unit = None;
        v.push(g);
    }
    v.push(
        Variable::real_parameter("state_scale", STATE_SCALE, "m", 1.0)
            .min(0.0)
            .describe("metres per state unit (1e-3: the state in mm and mm/s)"),
    );
    v
}

/// `m{i}`, `c{i}`, `k{i}`: the observer's model, at the structure's values.
fn observer_model(s: &Structure) -> Vec<Variable> {
    let mut v = Vec::new();
    for i in 0..s.storeys() {
        let k = i + 1;
        v.push(
            Variable::real_parameter(&format!("m{k}"), MASS + i as u32, "kg", s.mass[i])
                .min(0.0)
                .describe(&format!("mass of floor {k} (the observer's model)")),
        );
    }
    for i in 0..s.storeys() {
        let k = i + 1;
        v.push(
            Variable::real_parameter(&format!("c{k}"), DAMPING + i as u32, "N.s/m", s.damping[i])
                .min(0.0)
                .describe(&format!(
                    "viscous damping of storey {k} (the observer's model)"
                )),
        );
    }
    for i in 0..s.storeys() {
        let k = i + 1;
        v.push(
            Variable::real_parameter(
                &format!("k{k}"),
                STIFFNESS + i as u32,
                "N/m",
                s.stiffness[i],
            )
            .min(0.0)
            .describe(&format!("stiffness of storey {k} (the observer's model)")),
        );
    }
    v
}

/// `estimator` and its settings: `highpass_hz`, `process_sd`, `sensor_sd{j}`, `sample_interval`.
fn estimator_parameters(layout: &Layout) -> Vec<Variable> {
    let m = layout.measured.len();
    let mut v = vec![
        Variable::integer_parameter("estimator", ESTIMATOR, 0)
            .min(0.0)
            .max(1.0)
            .describe(&format!("0: integrate the accelerations with drift removal (highpass_hz; needs every floor's acceleration); 1: steady-state Kalman observer (process_sd, sensor_sd1..{m})")),
        Variable::real_parameter("highpass_hz", HIGHPASS_HZ, "Hz", DEFAULT_HIGHPASS_HZ)
            .min(0.0)
            .describe("corner of the integrating estimator's drift removal"),
    ];
    let (process_unit, process_what) = match layout.structure.excitation {
        Excitation::Force { floor } => ("N", format!("a white force error on floor {floor}")),
        Excitation::Base => ("m/s2", "a white ground acceleration error".to_owned()),
    };
    v.push(
        Variable::real_parameter("process_sd", PROCESS_SD, process_unit, DEFAULT_PROCESS_SD)
            .min(0.0)
            .describe(&format!("Kalman observer: sd of {process_what} per sample")),
    );
    for (j, c) in layout.measured.iter().enumerate() {
        let Channel::Response { quantity, .. } = *c else {
            continue;
        };
        v.push(
            Variable::real_parameter(
                &format!("sensor_sd{}", j + 1),
                SENSOR_SD + j as u32,
                unit_of(quantity),
                DEFAULT_SENSOR_SD,
            )
            .min(0.0)
            .describe(&format!("Kalman observer: noise sd of {}", c.name())),
        );
    }
    v.push(
        Variable::real_parameter(
            "sample_interval",
            SAMPLE_INTERVAL,
            "s",
            DEFAULT_SAMPLE_INTERVAL,
        )
        .min(0.0)
        .describe(
            "the controller's sample interval: every fmi2DoStep must be this long (1e-9 relative)",
        ),
    );
    v
}

fn build(layout: &Layout) -> ModelInfo {
    let n = layout.storeys();
    let measured: Vec<String> = layout.measured.iter().map(Channel::name).collect();
    ModelInfo::new(
        &format!("LqrController{n}"),
        MODEL_IDENTIFIER,
        &format!(
            "LQR controller of a {n}-storey shear frame under {}, the actuator on floor {}: state estimated from {} (integration or Kalman observer), command f_c = K w computed at each fmi2DoStep and acting over the next step",
            layout.structure.excitation.describe(),
            layout.actuator_floor,
            measured.join(", ")
        ),
        env!("CARGO_PKG_VERSION"),
        variables(layout),
        units(),
        false,
        Some(DefaultExperiment { start_time: 0.0, stop_time: 20.0, step_size: DEFAULT_SAMPLE_INTERVAL }),
    )
    // Built from a checked layout; the unit tests build it for every storey count.
    .expect("the LQR FMU's variable table is consistent")
}

/// The paper's rig's table, built once.
pub fn info() -> &'static ModelInfo {
    static INFO: OnceLock<ModelInfo> = OnceLock::new();
    INFO.get_or_init(|| build(&Layout::default()))
}

/// The table of a checked layout, built once per layout and kept for the life of the library.
pub fn table(layout: &Layout) -> &'static ModelInfo {
    static TABLES: OnceLock<Mutex<Vec<(Layout, &'static ModelInfo)>>> = OnceLock::new();
    if layout.is_paper() {
        return info();
    }
    let tables = TABLES.get_or_init(Default::default);
    // A poisoned lock only means another thread panicked while pushing; the list is still whole.
    let mut tables = tables.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, info)) = tables.iter().find(|(l, _)| l == layout) {
        return info;
    }
    let info: &'static ModelInfo = Box::leak(Box::new(build(layout)));
    tables.push((layout.clone(), info));
    info
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_is_consistent() {
        assert_eq!(super::info().model_identifier, super::MODEL_IDENTIFIER);
    }

    #[test]
    fn the_default_damping_is_the_shear_fmus() {
        assert_eq!(super::DEFAULT_DAMPING, (-4.605f64).exp());
    }

    /// Every storey count and both excitations, the actuator on the top floor, a mixed channel
    /// set: the table builds (distinct names and references), with 2N gains, N of each of m, c,
    /// k, one input and one sensor sd per measured channel, and the excitation's input alone.
    #[test]
    fn the_table_is_laid_out_for_every_storey_count() {
        let mut guids = std::collections::HashSet::new();
        for storeys in [1, 2, 3, 5, 10, 20, MAX_STOREYS] {
            for excitation in [Excitation::Force { floor: storeys }, Excitation::Base] {
                let mut measured = every_acceleration(storeys);
                measured.extend((1..=storeys).flat_map(|floor| {
                    [Quantity::Velocity, Quantity::Displacement]
                        .map(|quantity| Channel::Response { quantity, floor })
                }));
                let layout = Layout {
                    structure: Structure::uniform(storeys, 5.0, 0.5, 4000.0, excitation),
                    actuator_floor: storeys,
                    measured,
                }
                .checked()
                .expect("a valid layout");
                let info = table(&layout);
                assert!(guids.insert(info.guid.clone()), "{storeys}: GUID shared");
                assert!(std::ptr::eq(info, table(&layout)), "built once");
                for i in 1..=2 * storeys {
                    assert!(info.by_name(&format!("gain{i}")).is_some());
                }
                assert!(info.by_name(&format!("gain{}", 2 * storeys + 1)).is_none());
                for i in 1..=storeys {
                    for name in ["m", "c", "k", "acc", "vel", "disp"] {
                        assert!(info.by_name(&format!("{name}{i}")).is_some(), "{name}{i}");
                    }
                }
                for j in 1..=3 * storeys {
                    assert!(info.by_name(&format!("sensor_sd{j}")).is_some());
                }
                let base = excitation == Excitation::Base;
                assert_eq!(info.by_name("ground_acc").is_some(), base);
                assert_eq!(info.by_name("force").is_some(), !base);
            }
        }
    }

    #[test]
    fn a_layout_the_structure_cannot_have_is_refused() {
        let paper = Layout::default();
        let mut l = paper.clone();
        l.actuator_floor = 4;
        assert!(l.checked().unwrap_err().contains("actuator_floor = 4"));
        let mut l = paper.clone();
        l.measured = vec![Channel::parse("acc5").expect("a channel")];
        assert!(l.checked().unwrap_err().contains("acc5"));
        let mut l = paper;
        l.measured = vec![Channel::parse("acc1").expect("a channel"); 2];
        assert!(l.checked().unwrap_err().contains("twice"));
        // Without channels: every floor's acceleration, the paper's table.
        let l = Layout {
            measured: Vec::new(),
            ..Layout::default()
        };
        assert!(l.checked().expect("valid").is_paper());
    }
}
