//! The physics run: the twin's physics component run through FMI on the record, recording every
//! floor's acceleration, velocity and displacement and every storey's drift; its real parameter
//! values; and the scales of the candidates' priors they give.

use std::collections::BTreeMap;

use structure::channel::Quantity;

use super::{DiagnoseError, Result, Scales};
use crate::cosim::import::{Fmu, ModelDescription, UnpackedFmu};
use crate::evaluation::stats::rms;
use crate::twin::data::Measurement;
use crate::twin::simulator::Simulator;
use crate::twin::{ParameterValue, Twin, PHYSICS};

/// One physics run: every floor's acceleration, velocity and displacement and every storey's
/// drift, floor (storey) 1 first.
#[derive(Clone)]
pub(super) struct PhysicsRun {
    /// Per floor: absolute accelerations, and velocities and displacements relative to the
    /// ground.
    pub(super) acc: Vec<Vec<f64>>,
    pub(super) velocity: Vec<Vec<f64>>,
    pub(super) displacement: Vec<Vec<f64>>,
    /// Per storey.
    pub(super) drift: Vec<Vec<f64>>,
}

impl PhysicsRun {
    /// Floor `floor`'s (from 0) series of `quantity`.
    pub(super) fn at(&self, floor: usize, quantity: Quantity) -> &[f64] {
        match quantity {
            Quantity::Velocity => &self.velocity[floor],
            Quantity::Displacement => &self.displacement[floor],
            _ => &self.acc[floor],
        }
    }
}

/// The storeys of the building `twin` models: its [`Twin::structure`] (what the record's guard
/// checked the record against), the one place a diagnosis learns them.
pub(crate) fn storeys_of(twin: &Twin) -> Result<usize> {
    Ok(twin.structure()?.storeys())
}

/// Run the physics component of `twin` with `extra` parameters (and `values` for `names`).
pub(super) fn run_physics(
    twin: &Twin,
    data: &Measurement,
    extra: &BTreeMap<String, ParameterValue>,
    names: &[String],
    values: &[f64],
) -> Result<PhysicsRun> {
    let component = twin
        .component(PHYSICS)
        .ok_or_else(|| DiagnoseError::Setup(format!("the twin has no '{PHYSICS}' component")))?;
    let fmu = Fmu::open(&component.fmu_path)?;
    let storeys = storeys_of(twin)?;
    let mut base = component.parameters.clone();
    base.extend(extra.clone());
    for n in names {
        base.remove(n);
    }
    let vrs = names
        .iter()
        .map(|n| fmu.value_reference(n))
        .collect::<Result<Vec<u32>, _>>()?;
    let recorded: Vec<String> = ["acc", "drift", "vel", "disp"]
        .iter()
        .flat_map(|q| (1..=storeys).map(move |i| format!("{q}{i}")))
        .collect();
    let outputs = recorded
        .iter()
        .map(|n| fmu.value_reference(n))
        .collect::<Result<Vec<u32>, _>>()?;
    let mut sim = Simulator::for_record(&fmu, base, data, "diagnose")?;
    let mut out: Vec<Vec<f64>> = vec![Vec::new(); recorded.len()];
    sim.record(&vrs, values, &outputs, &mut out)?;
    let displacement = out.split_off(3 * storeys);
    let velocity = out.split_off(2 * storeys);
    let drift = out.split_off(storeys);
    Ok(PhysicsRun {
        acc: out,
        velocity,
        displacement,
        drift,
    })
}

/// The physics component's real parameters: the twin's value, else the FMU's start value, read
/// from its modelDescription, which is opened once.
pub(super) struct PhysicsReals {
    /// The building's storeys.
    pub(super) storeys: usize,
    pub(super) given: BTreeMap<String, ParameterValue>,
    pub(super) model_description: ModelDescription,
    pub(super) fmu_name: String,
}

impl PhysicsReals {
    pub(super) fn of(twin: &Twin) -> Result<Self> {
        let component = twin.component(PHYSICS).ok_or_else(|| {
            DiagnoseError::Setup(format!("the twin has no '{PHYSICS}' component"))
        })?;
        // The model description alone: nothing here runs the FMU.
        let model_description = UnpackedFmu::open(&component.fmu_path)?.model_description;
        Ok(PhysicsReals {
            storeys: storeys_of(twin)?,
            given: component.parameters.clone(),
            model_description,
            fmu_name: component.fmu_name.clone(),
        })
    }

    /// The structure's fastest undamped mode (Hz) at these values.
    pub(super) fn fastest_mode_hz(&self) -> Result<f64> {
        let per_storey = |p: char| -> Result<Vec<f64>> {
            (1..=self.storeys)
                .map(|i| self.get(&format!("{p}{i}")))
                .collect()
        };
        let structure = ::structure::building::Structure {
            mass: per_storey('m')?,
            damping: per_storey('c')?,
            stiffness: per_storey('k')?,
            excitation: Default::default(),
        };
        Ok(structure
            .natural_frequencies()
            .last()
            .copied()
            .unwrap_or(f64::NAN))
    }

    pub(super) fn get(&self, name: &str) -> Result<f64> {
        if let Some(ParameterValue::Real(x)) = self.given.get(name) {
            return Ok(*x);
        }
        self.model_description
            .variable(name)
            .and_then(|v| v.start.as_deref())
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| {
                DiagnoseError::Setup(format!("{}: no value for '{name}'", self.fmu_name))
            })
    }
}

/// The scales of the candidates' priors on this record: the twin's storey stiffness, and the
/// RMS after the transient of the physics run's drifts and velocities and of the force.
pub(super) fn prior_scales(
    reals: &PhysicsReals,
    run: &PhysicsRun,
    data: &Measurement,
    first: usize,
) -> Result<Scales> {
    let stiffness = (1..=run.drift.len())
        .map(|s| reals.get(&format!("k{s}")))
        .collect::<Result<Vec<f64>>>()?;
    // The load's size: the force, or under ground motion the whole building's inertia times
    // the ground's acceleration (the load −M·1·a_g of the relative coordinates).
    let load = match data.excitation.channel {
        ::structure::channel::Channel::Excitation(::structure::channel::ExcitationKind::Force) => {
            1.0
        }
        _ => (1..=run.drift.len())
            .map(|f| reals.get(&format!("m{f}")))
            .sum::<Result<f64>>()?,
    };
    Ok(Scales {
        stiffness,
        drift_rms: run.drift.iter().map(|d| rms(&d[first..])).collect(),
        velocity_rms: run.velocity.iter().map(|v| rms(&v[first..])).collect(),
        force_rms: load * rms(&data.excitation.values[first..]),
    })
}
