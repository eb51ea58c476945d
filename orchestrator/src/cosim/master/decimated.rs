//! Multi-rate co-simulation: a slave that keeps a slower rate than the master's clock. It takes
//! its inputs and one step every `every` communication points (the step spanning them), and holds
//! its outputs in between — a sampled-data model (the GP corrector's lags are the record's
//! samples) beside a fast one (a controller's loop).

use super::{MasterError, Slave};

pub struct Decimated {
    inner: Box<dyn Slave>,
    every: usize,
    /// Communication points seen so far (= the index of the next `do_step`).
    calls: usize,
    /// Where the pending long step starts.
    window_start: f64,
}

impl Decimated {
    /// `every` ≥ 1 master steps per step of `inner`.
    pub fn new(inner: Box<dyn Slave>, every: usize) -> Result<Self, MasterError> {
        if every == 0 {
            return Err(MasterError::Config(
                "a decimated slave needs at least one master step per step".into(),
            ));
        }
        Ok(Decimated {
            inner,
            every,
            calls: 0,
            window_start: f64::NAN,
        })
    }

    /// Whether the current point is one of the slave's own.
    fn on_own_point(&self) -> bool {
        self.calls.is_multiple_of(self.every)
    }
}

impl Slave for Decimated {
    fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), MasterError> {
        if self.on_own_point() {
            self.inner.set_real(vrs, values)
        } else {
            Ok(())
        }
    }

    fn get_real(&mut self, vrs: &[u32], values: &mut [f64]) -> Result<(), MasterError> {
        self.inner.get_real(vrs, values)
    }

    fn set_boolean(&mut self, vrs: &[u32], values: &[bool]) -> Result<(), MasterError> {
        if self.on_own_point() {
            self.inner.set_boolean(vrs, values)
        } else {
            Ok(())
        }
    }

    fn get_boolean(&mut self, vrs: &[u32], values: &mut [bool]) -> Result<(), MasterError> {
        self.inner.get_boolean(vrs, values)
    }

    /// Inputs are held over the long step.
    fn set_real_input_derivatives(
        &mut self,
        _vrs: &[u32],
        _slopes: &[f64],
    ) -> Result<(), MasterError> {
        Ok(())
    }

    fn can_interpolate_inputs(&self) -> bool {
        false
    }

    fn do_step(&mut self, time: f64, step: f64) -> Result<(), MasterError> {
        if self.on_own_point() {
            self.window_start = time;
        }
        self.calls += 1;
        if self.on_own_point() {
            self.inner
                .do_step(self.window_start, time + step - self.window_start)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::RefCell;
    use std::rc::Rc;

    /// Records what reaches it.
    struct Log {
        events: Rc<RefCell<Vec<String>>>,
    }

    impl Slave for Log {
        fn set_real(&mut self, _vrs: &[u32], values: &[f64]) -> Result<(), MasterError> {
            self.events.borrow_mut().push(format!("set {}", values[0]));
            Ok(())
        }
        fn get_real(&mut self, _vrs: &[u32], values: &mut [f64]) -> Result<(), MasterError> {
            values.fill(0.0);
            Ok(())
        }
        fn set_real_input_derivatives(&mut self, _: &[u32], _: &[f64]) -> Result<(), MasterError> {
            Ok(())
        }
        fn can_interpolate_inputs(&self) -> bool {
            true
        }
        fn do_step(&mut self, time: f64, step: f64) -> Result<(), MasterError> {
            self.events.borrow_mut().push(format!("step {time} {step}"));
            Ok(())
        }
    }

    #[test]
    fn steps_and_inputs_reach_the_slave_at_its_own_rate() {
        let events = Rc::new(RefCell::new(Vec::new()));
        let mut d = Decimated::new(
            Box::new(Log {
                events: events.clone(),
            }),
            4,
        )
        .expect("valid");
        for k in 0..8 {
            let t = k as f64 * 0.25;
            d.set_real(&[0], &[k as f64]).expect("set");
            d.do_step(t, 0.25).expect("step");
        }
        assert_eq!(
            *events.borrow(),
            vec!["set 0", "step 0 1", "set 4", "step 1 1"]
        );
        assert!(!d.can_interpolate_inputs());
        assert!(Decimated::new(Box::new(Log { events }), 0).is_err());
    }
}
