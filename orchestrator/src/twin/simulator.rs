//! One FMU instance run again and again on one record, with different parameter values: the
//! inner loop of calibration. The runs are the master algorithm's (`master::System`: the record's
//! excitation, `force` or `ground_acc`, replayed into the instance), so its predictions are
//! `twin compare`'s by construction.

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::rc::Rc;

use crate::cosim::import::{Causality, Fmu, Instance, ScalarType, StepEnd};
use crate::cosim::master::{Clock, MasterError, Port, Recorder, Slave, System};
use crate::twin::data::Measurement;
use crate::twin::system::initialise;
use crate::twin::{ParameterValue, TwinError};

/// One FMU instance run on the master, the record's excitation replayed into the input of its
/// name (`force` or `ground_acc`). Between runs the simulator resets the instance and sets its
/// parameters.
pub struct Simulator<'a> {
    fmu: &'a Fmu,
    instance: Rc<RefCell<Instance>>,
    name: String,
    /// The twin's own parameter values for this component, applied before the calibrated ones.
    base: BTreeMap<String, ParameterValue>,
    /// The excitation's input and its values.
    force_vr: u32,
    force: &'a [f64],
    start: f64,
    dt: f64,
}

impl<'a> Simulator<'a> {
    /// `excitation` replayed into the FMU's input `input` (`force` or `ground_acc`); the
    /// outputs are the caller's ([`Simulator::record`]).
    pub fn driven(
        fmu: &'a Fmu,
        base: BTreeMap<String, ParameterValue>,
        input: &str,
        excitation: &'a [f64],
        start: f64,
        dt: f64,
        name: &str,
    ) -> Result<Self, TwinError> {
        let instance = Rc::new(RefCell::new(fmu.instantiate(name)?));
        let force_vr = fmu.value_reference(input)?;
        let force = excitation;
        Ok(Simulator {
            fmu,
            instance,
            name: name.to_owned(),
            base,
            force_vr,
            force,
            start,
            dt,
        })
    }

    /// The physics with `base` driven by `data`'s excitation (`force` or `ground_acc`) from its
    /// first time, at its interval.
    pub fn for_record(
        fmu: &'a Fmu,
        base: BTreeMap<String, ParameterValue>,
        data: &'a Measurement,
        name: &str,
    ) -> Result<Self, TwinError> {
        Self::driven(
            fmu,
            base,
            &data.excitation.channel.name(),
            &data.excitation.values,
            data.time[0],
            data.dt,
            name,
        )
    }

    /// Like [`Simulator::simulate`], but records the real outputs `outputs` (value
    /// references): `out[i][k]` is output i at sample k.
    pub fn record(
        &mut self,
        vrs: &[u32],
        values: &[f64],
        outputs: &[u32],
        out: &mut [Vec<f64>],
    ) -> Result<(), TwinError> {
        self.run(vrs, values, None, outputs, out)
    }

    /// Like [`Simulator::record`], with the Boolean parameter `switch` (e.g. the shear FMU's
    /// `sensitivities`) set for this run only.
    pub fn record_switched(
        &mut self,
        vrs: &[u32],
        values: &[f64],
        switch: u32,
        outputs: &[u32],
        out: &mut [Vec<f64>],
    ) -> Result<(), TwinError> {
        self.run(vrs, values, Some(switch), outputs, out)
    }

    /// Like [`Simulator::record_switched`], but each sample's values of `outputs` go to `each`
    /// as the run makes them, none kept: for outputs too many to hold (a Jacobian, samples ×
    /// channels × parameters) that are reduced on the way.
    pub fn stream_switched(
        &mut self,
        vrs: &[u32],
        values: &[f64],
        switch: u32,
        outputs: &[u32],
        each: impl FnMut(&[f64]),
    ) -> Result<(), TwinError> {
        self.prepare(vrs, values, Some(switch))?;
        if self.force.is_empty() {
            return Ok(());
        }
        let (mut system, node) = self.system(outputs)?;
        let mut stream = Stream {
            ports: (0..outputs.len()).map(|i| Port::Output(node, i)).collect(),
            each,
        };
        let clock = Clock::new(self.start, self.dt, (self.force.len() - 1) as u64);
        system
            .run(clock, &mut [&mut stream], |_, _| {})
            .map_err(master_error)?;
        Ok(())
    }

    /// Reset the instance and initialise it with `vrs` = `values` (and `switch` on).
    fn prepare(
        &mut self,
        vrs: &[u32],
        values: &[f64],
        switch: Option<u32>,
    ) -> Result<(), TwinError> {
        let mut inst = self.instance.borrow_mut();
        inst.reset()?;
        initialise(self.fmu, &mut inst, self.start, &self.base, |inst| {
            if let Some(switch) = switch {
                inst.set_boolean(&[switch], &[true])?;
            }
            Ok(inst.set_real(vrs, values)?)
        })
    }

    /// The master's system: the record's excitation into the instance, `outputs` its ports.
    fn system(&self, outputs: &[u32]) -> Result<(System, crate::cosim::master::NodeId), TwinError> {
        let mut system = System::new();
        let node = system.add_slave(
            &self.name,
            Box::new(Shared(Rc::clone(&self.instance))),
            vec![self.force_vr],
            outputs.to_vec(),
        );
        let force = system.add_signal("force", self.force.to_vec());
        system.connect(force, node, 0).map_err(master_error)?;
        Ok((system, node))
    }

    fn run(
        &mut self,
        vrs: &[u32],
        values: &[f64],
        switch: Option<u32>,
        outputs: &[u32],
        out: &mut [Vec<f64>],
    ) -> Result<(), TwinError> {
        self.prepare(vrs, values, switch)?;
        for o in out.iter_mut() {
            o.clear();
        }
        if self.force.is_empty() {
            return Ok(());
        }
        let (mut system, node) = self.system(outputs)?;
        let mut recorder = Recorder::with_capacity(
            (0..outputs.len())
                .map(|i| (i.to_string(), Port::Output(node, i)))
                .collect(),
            self.force.len(),
        );
        let clock = Clock::new(self.start, self.dt, (self.force.len() - 1) as u64);
        system
            .run(clock, &mut [&mut recorder], |_, _| {})
            .map_err(master_error)?;
        for (o, column) in out.iter_mut().zip(recorder.columns) {
            *o = column;
        }
        Ok(())
    }
}

/// An observer handing each sample's values to a closure.
struct Stream<F> {
    ports: Vec<Port>,
    each: F,
}

impl<F: FnMut(&[f64])> crate::cosim::master::Observer for Stream<F> {
    fn record(&mut self, _time: f64, values: &[f64]) {
        (self.each)(values);
    }
    fn ports(&self) -> &[Port] {
        &self.ports
    }
}

/// The instance as the master's slave, shared with the simulator that resets it between runs.
struct Shared(Rc<RefCell<Instance>>);

impl Slave for Shared {
    fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), MasterError> {
        Slave::set_real(&mut *self.0.borrow_mut(), vrs, values)
    }
    fn get_real(&mut self, vrs: &[u32], values: &mut [f64]) -> Result<(), MasterError> {
        Slave::get_real(&mut *self.0.borrow_mut(), vrs, values)
    }
    fn set_real_input_derivatives(
        &mut self,
        vrs: &[u32],
        slopes: &[f64],
    ) -> Result<(), MasterError> {
        Slave::set_real_input_derivatives(&mut *self.0.borrow_mut(), vrs, slopes)
    }
    fn can_interpolate_inputs(&self) -> bool {
        Slave::can_interpolate_inputs(&*self.0.borrow())
    }
    fn do_step(&mut self, time: f64, step: f64) -> Result<(), MasterError> {
        Slave::do_step(&mut *self.0.borrow_mut(), time, step)
    }
    fn step(&mut self, time: f64, step: f64) -> Result<StepEnd, MasterError> {
        Slave::step(&mut *self.0.borrow_mut(), time, step)
    }
}

/// An import error stays one (calibration and diagnosis report it as such); the master's own
/// errors (configuration, a failure at a time) keep their text.
fn master_error(e: MasterError) -> TwinError {
    match e {
        MasterError::Import(e) => TwinError::Import(e),
        other => TwinError::Message(other.to_string()),
    }
}

/// The value reference of the FMU's Boolean parameter that switches its forward sensitivities
/// on, if it has one.
pub(crate) fn sensitivity_switch(fmu: &Fmu) -> Option<u32> {
    let switch = fmu
        .model_description
        .variable("sensitivities")
        .filter(|v| v.scalar_type == ScalarType::Boolean && v.causality == Causality::Parameter)?;
    Some(switch.value_reference)
}

/// The value references of `d_{channel}_d_{p}` for every calibrated parameter, if the FMU has
/// them all.
pub(crate) fn channel_sensitivities(
    fmu: &Fmu,
    channel: &str,
    parameters: &[String],
) -> Option<Vec<u32>> {
    parameters
        .iter()
        .map(|p| {
            fmu.model_description
                .variable(&format!("d_{channel}_d_{p}"))
                .map(|v| v.value_reference)
        })
        .collect()
}
