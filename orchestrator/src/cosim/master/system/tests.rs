use super::*;
use crate::cosim::master::Recorder;

/// A slave integrating `ẋ = u` exactly for linear `u`; output 0 is `x`, output 1 is `u`
/// (direct feedthrough), output 2 is `x + u`.
struct Integrator {
    x: f64,
    u: f64,
    slope: f64,
    interpolate: bool,
    steps: Vec<(f64, f64)>,
}

impl Integrator {
    fn new(interpolate: bool) -> Self {
        Integrator {
            x: 0.0,
            u: 0.0,
            slope: 0.0,
            interpolate,
            steps: Vec::new(),
        }
    }
}

impl Slave for Integrator {
    fn set_real(&mut self, _vrs: &[u32], values: &[f64]) -> Result<(), MasterError> {
        self.u = values[0];
        Ok(())
    }
    fn get_real(&mut self, vrs: &[u32], values: &mut [f64]) -> Result<(), MasterError> {
        for (slot, vr) in values.iter_mut().zip(vrs) {
            *slot = match vr {
                0 => self.x,
                1 => self.u,
                _ => self.x + self.u,
            };
        }
        Ok(())
    }
    fn set_real_input_derivatives(
        &mut self,
        _vrs: &[u32],
        slopes: &[f64],
    ) -> Result<(), MasterError> {
        self.slope = slopes[0];
        Ok(())
    }
    fn can_interpolate_inputs(&self) -> bool {
        self.interpolate
    }
    fn do_step(&mut self, time: f64, step: f64) -> Result<(), MasterError> {
        self.steps.push((time, step));
        self.x += self.u * step + 0.5 * self.slope * step * step;
        self.u += self.slope * step;
        Ok(())
    }
    fn save_state(&mut self) -> Result<Vec<u8>, MasterError> {
        Ok([self.x, self.u, self.slope]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect())
    }
    fn restore_state(&mut self, state: &[u8]) -> Result<(), MasterError> {
        let value =
            |i: usize| f64::from_le_bytes(state[8 * i..8 * i + 8].try_into().expect("8 bytes"));
        (self.x, self.u, self.slope) = (value(0), value(1), value(2));
        Ok(())
    }
}

fn run_integrator(interpolate: bool, samples: Vec<f64>, steps: u64, h: f64) -> Vec<f64> {
    let mut system = System::new();
    let n = system.add_slave(
        "int",
        Box::new(Integrator::new(interpolate)),
        vec![10],
        vec![0],
    );
    let s = system.add_signal("u", samples);
    system.connect(s, n, 0).expect("connect");
    let mut rec = Recorder::new(vec![("x".into(), Port::Output(n, 0))]);
    system
        .run(Clock::new(0.0, h, steps), &mut [&mut rec], |_, _| {})
        .expect("runs");
    rec.columns[0].clone()
}

#[test]
fn replayed_signals_are_linear_inside_a_step_when_the_slave_interpolates() {
    // u(t) = t sampled at 0, 0.5, 1, 1.5, 2: x(t) = t²/2 exactly with first-order inputs.
    let h = 0.5;
    let samples: Vec<f64> = (0..5).map(|k| k as f64 * h).collect();
    let x = run_integrator(true, samples.clone(), 4, h);
    for (k, xk) in x.iter().enumerate() {
        let t = k as f64 * h;
        assert!((xk - t * t / 2.0).abs() < 1e-15, "k = {k}: {xk}");
    }
    // Without interpolation the input is held: a zero-order hold lags by h/2·t.
    let held = run_integrator(false, samples, 4, h);
    assert!(
        (x[4] - held[4] - 0.5).abs() < 1e-12,
        "hold loses h·t_end/2 = 0.5: {} vs {}",
        x[4],
        held[4]
    );
}

#[test]
fn time_is_exact_and_steps_follow_each_other() {
    let mut system = System::new();
    let n = system.add_slave("int", Box::new(Integrator::new(true)), vec![10], vec![0]);
    let s = system.add_signal("u", vec![1.0; 1025]);
    system.connect(s, n, 0).expect("connect");
    let mut rec = Recorder::new(vec![("x".into(), Port::Output(n, 0))]);
    let clock = Clock::new(0.0, 1.0 / 51.2, 1024);
    system.run(clock, &mut [&mut rec], |_, _| {}).expect("runs");
    assert_eq!(rec.time.len(), 1025);
    assert_eq!(*rec.time.last().expect("points"), 20.0);
    assert!((rec.columns[0][1024] - 20.0).abs() < 1e-12);
}

/// Two slaves: A's feedthrough output u feeds B. With Gauss–Seidel, B sees A's value at
/// the same point; with Jacobi, one point late.
#[test]
fn gauss_seidel_sees_fresh_values_and_jacobi_the_previous_ones() {
    let run = |algorithm: Algorithm| {
        let mut system = System::new();
        system.algorithm = algorithm;
        let a = system.add_slave("a", Box::new(Integrator::new(false)), vec![10], vec![1]);
        let b = system.add_slave("b", Box::new(Integrator::new(false)), vec![10], vec![1]);
        let s = system.add_signal("u", vec![0.0, 1.0, 2.0, 3.0]);
        system.connect(s, a, 0).expect("connect");
        system.connect(Port::Output(a, 0), b, 0).expect("connect");
        let mut rec = Recorder::new(vec![("b.u".into(), Port::Output(b, 0))]);
        system
            .run(Clock::new(0.0, 1.0, 3), &mut [&mut rec], |_, _| {})
            .expect("runs");
        rec.columns[0].clone()
    };
    assert_eq!(run(Algorithm::GaussSeidel), vec![0.0, 1.0, 2.0, 3.0]);
    assert_eq!(run(Algorithm::Jacobi), vec![0.0, 0.0, 1.0, 2.0]);
}

/// A feedback loop through a zero-time block: block output = −2·(slave's x), fed back as
/// the slave's input. Gauss–Seidel settles the loop at each point.
#[test]
fn blocks_close_loops_in_zero_time() {
    let mut system = System::new();
    let slave = system.add_slave("int", Box::new(Integrator::new(false)), vec![10], vec![2]);
    let gain = system.add_block(
        "gain",
        Box::new(|_t: f64, inputs: &[f64], outputs: &mut [f64]| {
            outputs[0] = 1.0 - inputs[0];
            Ok(())
        }),
        1,
        1,
    );
    // slave output 2 = x + u depends on u (feedthrough), block output feeds u: the block
    // sees x + u, so u = 1 − (x + u) → u = (1 − x)/2 is an algebraic loop; GS iterates it
    // and must report that it does not settle bit-exactly... unless it converges; here the
    // iteration u ← 1 − x − u oscillates, so an error is expected.
    system
        .connect(Port::Output(slave, 0), gain, 0)
        .expect("connect");
    system
        .connect(Port::Output(gain, 0), slave, 0)
        .expect("connect");
    let mut rec = Recorder::new(vec![("x".into(), Port::Output(slave, 0))]);
    let err = system
        .run(Clock::new(0.0, 0.1, 10), &mut [&mut rec], |_, _| {})
        .expect_err("algebraic loop");
    assert!(err.to_string().contains("algebraic loop"), "{err}");
}

#[test]
fn loops_through_non_feedthrough_outputs_settle() {
    // Slave output 0 = x (no feedthrough); block u = −x; so ẋ = −x: x(t) = x0·e^{−t}.
    // Starting from x = 0 with an extra constant signal is simpler: block u = 1 − x.
    let mut system = System::new();
    let slave = system.add_slave("int", Box::new(Integrator::new(false)), vec![10], vec![0]);
    let block = system.add_block(
        "ctrl",
        Box::new(|_t: f64, inputs: &[f64], outputs: &mut [f64]| {
            outputs[0] = 1.0 - inputs[0];
            Ok(())
        }),
        1,
        1,
    );
    system
        .connect(Port::Output(slave, 0), block, 0)
        .expect("connect");
    system
        .connect(Port::Output(block, 0), slave, 0)
        .expect("connect");
    let h = 0.01;
    let mut rec = Recorder::new(vec![("x".into(), Port::Output(slave, 0))]);
    system
        .run(Clock::new(0.0, h, 100), &mut [&mut rec], |_, _| {})
        .expect("runs");
    // Explicit Euler of ẋ = 1 − x: x_k = 1 − (1 − h)^k, exactly, if the control is applied
    // at the same point (no one-step delay).
    let expected = 1.0 - (1.0f64 - h).powi(100);
    assert!(
        (rec.columns[0][100] - expected).abs() < 1e-12,
        "{} vs {expected}",
        rec.columns[0][100]
    );
}

/// The loop of `blocks_close_loops_in_zero_time`, sampled: the block reads `x + u` as the
/// step left it (`x_k + u_{k−1}`), so the loop closes once per point and follows the
/// discrete controller's recurrence exactly.
#[test]
fn sampled_connections_close_feedthrough_loops_as_a_digital_controller() {
    let mut system = System::new();
    let slave = system.add_slave("int", Box::new(Integrator::new(false)), vec![10], vec![2]);
    let calls = std::rc::Rc::new(std::cell::Cell::new(0usize));
    let counter = calls.clone();
    let block = system.add_block(
        "ctrl",
        Box::new(move |_t: f64, inputs: &[f64], outputs: &mut [f64]| {
            counter.set(counter.get() + 1);
            outputs[0] = 1.0 - inputs[0];
            Ok(())
        }),
        1,
        1,
    );
    system
        .connect_sampled(Port::Output(slave, 0), block, 0)
        .expect("connect");
    system
        .connect(Port::Output(block, 0), slave, 0)
        .expect("connect");
    assert!(system.connect_sampled(Port::Signal(0), block, 0).is_err());
    let (h, steps) = (0.1, 10);
    let mut rec = Recorder::new(vec![
        ("x+u".into(), Port::Output(slave, 0)),
        ("u".into(), Port::Output(block, 0)),
    ]);
    system
        .run(Clock::new(0.0, h, steps), &mut [&mut rec], |_, _| {})
        .expect("a sampled loop settles");
    let (mut x, mut u) = (0.0f64, 0.0f64);
    for k in 0..=steps as usize {
        u = 1.0 - (x + u);
        assert!((rec.columns[1][k] - u).abs() < 1e-15, "u at k = {k}");
        assert!(
            (rec.columns[0][k] - (x + u)).abs() < 1e-15,
            "x + u at k = {k}"
        );
        x += h * u;
    }
    assert_eq!(calls.get(), steps as usize + 1, "one evaluation per point");
}

/// A: ẋ = u from a signal (interpolated), a block doubling A's x, B integrating that: a
/// coupled system. `signal` None: the samples are set point by point.
fn coupled(samples: Option<Vec<f64>>) -> (System, Port, [Port; 2]) {
    let mut system = System::new();
    let a = system.add_slave("a", Box::new(Integrator::new(true)), vec![10], vec![0]);
    let double = system.add_block(
        "double",
        Box::new(|_t: f64, inputs: &[f64], outputs: &mut [f64]| {
            outputs[0] = 2.0 * inputs[0];
            Ok(())
        }),
        1,
        1,
    );
    let b = system.add_slave("b", Box::new(Integrator::new(false)), vec![10], vec![0]);
    let s = system.add_signal("u", samples.unwrap_or_default());
    system.connect(s, a, 0).expect("connect");
    system
        .connect(Port::Output(a, 0), double, 0)
        .expect("connect");
    system
        .connect(Port::Output(double, 0), b, 0)
        .expect("connect");
    (system, s, [Port::Output(a, 0), Port::Output(b, 0)])
}

#[test]
fn stepping_point_by_point_is_the_run() {
    let h = 0.25;
    let samples: Vec<f64> = (0..9).map(|k| (0.7 * k as f64).sin()).collect();
    let steps = samples.len() as u64 - 1;
    let (mut batch, _, ports) = coupled(Some(samples.clone()));
    let mut rec = Recorder::new(vec![("a".into(), ports[0]), ("b".into(), ports[1])]);
    batch
        .run(Clock::new(0.0, h, steps), &mut [&mut rec], |_, _| {})
        .expect("runs");

    let (mut stepped, u, ports) = coupled(None);
    assert!(stepped.step(h).is_err(), "a step before the first point");
    stepped.set_input(u, samples[0]).expect("a signal");
    stepped.initialize(0.0).expect("the first point");
    let mut values = vec![ports.map(|p| stepped.value(p))];
    for (k, &sample) in samples.iter().enumerate().skip(1) {
        stepped.set_input(u, sample).expect("a signal");
        let end = stepped.step(k as f64 * h).expect("a step");
        assert_eq!(end, StepEnd::Completed);
        values.push(ports.map(|p| stepped.value(p)));
    }
    for (k, v) in values.iter().enumerate() {
        assert_eq!(v[0].to_bits(), rec.columns[0][k].to_bits(), "a at k = {k}");
        assert_eq!(v[1].to_bits(), rec.columns[1][k].to_bits(), "b at k = {k}");
    }
    assert!(
        stepped.set_input(ports[0], 1.0).is_err(),
        "an output is no input"
    );
}

#[test]
fn a_saved_state_goes_on_in_another_system() {
    let h = 0.5;
    let samples = [0.0, 1.0, 3.0, 2.0, -1.0, 0.5];
    let system = || {
        let mut system = System::new();
        let a = system.add_slave("a", Box::new(Integrator::new(true)), vec![10], vec![0]);
        let s = system.add_signal("u", Vec::new());
        system.connect(s, a, 0).expect("connect");
        (system, s, Port::Output(a, 0))
    };
    let (mut first, u, x) = system();
    first.set_input(u, samples[0]).expect("a signal");
    first.initialize(0.0).expect("the first point");
    let mut saved = None;
    let mut rest = Vec::new();
    for (k, &sample) in samples.iter().enumerate().skip(1) {
        first.set_input(u, sample).expect("a signal");
        first.step(k as f64 * h).expect("a step");
        if k == 2 {
            saved = Some(first.save().expect("saves"));
        } else if k > 2 {
            rest.push(first.value(x));
        }
    }
    let saved = saved.expect("saved at k = 2");
    assert_eq!(saved.time, 1.0);
    let (mut second, u, x) = system();
    second.restore(&saved).expect("restores");
    assert_eq!(second.time(), Some(1.0));
    for (k, &sample) in samples.iter().enumerate().skip(3) {
        second.set_input(u, sample).expect("a signal");
        second.step(k as f64 * h).expect("a step");
        assert_eq!(second.value(x).to_bits(), rest[k - 3].to_bits(), "k = {k}");
    }
    // A system with a block has no state of its own to save.
    let (mut with_block, u, _) = coupled(None);
    with_block.set_input(u, 0.0).expect("a signal");
    with_block.initialize(0.0).expect("the first point");
    let err = with_block.save().expect_err("a block");
    assert!(err.to_string().contains("double"), "{err}");
}

#[test]
fn bad_connections_are_refused() {
    let mut system = System::new();
    let a = system.add_slave("a", Box::new(Integrator::new(false)), vec![10], vec![0]);
    assert!(system.connect(Port::Output(a, 5), a, 0).is_err());
    assert!(system.connect(Port::Signal(3), a, 0).is_err());
    let s = system.add_signal("u", vec![0.0; 2]);
    system.connect(s, a, 0).expect("first");
    assert!(
        system.connect(s, a, 0).is_err(),
        "an input takes one connection"
    );
    let mut rec = Recorder::new(vec![]);
    let err = system
        .run(Clock::new(0.0, 1.0, 5), &mut [&mut rec], |_, _| {})
        .expect_err("short signal");
    assert!(err.to_string().contains("samples"), "{err}");
}
