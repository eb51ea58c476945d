//! One FMU instance run again and again on one record, with different parameter values: the
//! inner loop of calibration. Same input convention as the master algorithm (inputs set at
//! `t_k`, outputs read, then the segment's slope, then the step), so its predictions equal
//! `twin compare`'s bit for bit.

use std::collections::BTreeMap;

use crate::import::{Fmu, ImportError, Instance};
use crate::twin::{apply_parameters, ParameterValue, TwinError, OUTPUTS};

pub struct Simulator<'a> {
    fmu: &'a Fmu,
    instance: Instance,
    /// The twin's own parameter values for this component, applied before the calibrated ones.
    base: BTreeMap<String, ParameterValue>,
    force_vr: u32,
    acc_vrs: [u32; 3],
    force: &'a [f64],
    start: f64,
    dt: f64,
}

impl<'a> Simulator<'a> {
    pub fn new(
        fmu: &'a Fmu,
        base: BTreeMap<String, ParameterValue>,
        force: &'a [f64],
        start: f64,
        dt: f64,
        name: &str,
    ) -> Result<Self, TwinError> {
        let instance = fmu.instantiate(name)?;
        let force_vr = fmu.value_reference("force")?;
        let acc_vrs = [
            fmu.value_reference(OUTPUTS[0])?,
            fmu.value_reference(OUTPUTS[1])?,
            fmu.value_reference(OUTPUTS[2])?,
        ];
        Ok(Simulator {
            fmu,
            instance,
            base,
            force_vr,
            acc_vrs,
            force,
            start,
            dt,
        })
    }

    /// Simulate with the real parameters `vrs` set to `values`; `out[f][k]` is floor f's
    /// acceleration at sample k.
    pub fn simulate(
        &mut self,
        vrs: &[u32],
        values: &[f64],
        out: &mut [Vec<f64>; 3],
    ) -> Result<(), TwinError> {
        let acc_vrs = self.acc_vrs;
        self.record(vrs, values, &acc_vrs, out)
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
        let n = self.force.len();
        let inst = &mut self.instance;
        inst.reset()?;
        inst.setup_experiment(self.start, None)?;
        inst.enter_initialization_mode()?;
        apply_parameters(self.fmu, inst, &self.base)?;
        inst.set_real(vrs, values)?;
        inst.exit_initialization_mode()?;
        for o in out.iter_mut() {
            o.resize(n, 0.0);
        }
        let mut read = vec![0.0; outputs.len()];
        for k in 0..n {
            let time = self.start + k as f64 * self.dt;
            inst.set_real(&[self.force_vr], &[self.force[k]])?;
            inst.get_real(outputs, &mut read)?;
            for (o, v) in out.iter_mut().zip(&read) {
                o[k] = *v;
            }
            if k + 1 < n {
                let slope = (self.force[k + 1] - self.force[k]) / self.dt;
                if inst.can_interpolate_inputs() {
                    inst.set_real_input_derivatives(&[self.force_vr], &[slope])?;
                }
                step(inst, time, self.dt)?;
            }
        }
        Ok(())
    }
}

fn step(inst: &mut Instance, time: f64, dt: f64) -> Result<(), ImportError> {
    inst.do_step(time, dt)
}
