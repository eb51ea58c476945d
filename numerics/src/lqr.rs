//! The shear structure's state-space model and the LQR controller's run-time law (the reference
//! paper's section 6, eqs 16–22): `f_c = K ŵ`, with the state `ŵ = [y; ẏ]` estimated from the
//! measured floor accelerations, either by integrating them with drift removal (as the paper
//! does) or by a steady-state Kalman observer on the twin's model.
//!
//! The same code runs as a block of the orchestrator's master and inside the controller FMU, so
//! a controlled system gives the same numbers in any FMI host.
//!
//! Units: physical quantities in SI (m, N, kg); the state may be expressed in other units
//! through `state_scale` (metres per state unit: 1e-3 for the paper's millimetres), and then the
//! gain is in newtons per state unit.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use serde::{Deserialize, Serialize};

/// Floors of the structure.
pub const FLOORS: usize = 3;
/// States: displacements then velocities of the floors.
pub const STATES: usize = 2 * FLOORS;

pub type StateMatrix = SMatrix<f64, STATES, STATES>;
pub type StateVector = SVector<f64, STATES>;

/// Errors of the controller's set-up.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum LqrError {
    #[error("{what} must be finite and positive, got {value}")]
    NotPositive { what: String, value: f64 },
    #[error("the gain has a non-finite entry: {0:?}")]
    NonFiniteGain([f64; STATES]),
    #[error("the mass matrix is singular")]
    SingularMass,
    #[error("the Kalman observer's covariance did not settle in {0} iterations")]
    KalmanNotConverged(usize),
    #[error("the Kalman observer's innovation covariance is singular")]
    SingularInnovation,
}

fn positive(what: &str, value: f64) -> Result<f64, LqrError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(LqrError::NotPositive {
            what: what.to_owned(),
            value,
        })
    }
}

/// Masses (kg), storey dampings (N s/m) and storey stiffnesses (N/m) of the shear model: the
/// linear part of eq. (16).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShearMatrices {
    pub mass: [f64; FLOORS],
    pub damping: [f64; FLOORS],
    pub stiffness: [f64; FLOORS],
}

/// The tridiagonal matrix of storey coefficients `c` (storey i joins floor i−1 and floor i;
/// storey 1 joins the ground and floor 1).
fn storey_matrix(c: &[f64; FLOORS]) -> Matrix3<f64> {
    let mut m = Matrix3::zeros();
    for i in 0..FLOORS {
        m[(i, i)] += c[i];
        if i + 1 < FLOORS {
            m[(i, i)] += c[i + 1];
            m[(i, i + 1)] -= c[i + 1];
            m[(i + 1, i)] -= c[i + 1];
        }
    }
    m
}

impl ShearMatrices {
    /// Every value finite, masses and stiffnesses positive, dampings non-negative.
    pub fn check(&self) -> Result<(), LqrError> {
        for i in 0..FLOORS {
            positive(&format!("m{}", i + 1), self.mass[i])?;
            positive(&format!("k{}", i + 1), self.stiffness[i])?;
            let c = self.damping[i];
            if !(c.is_finite() && c >= 0.0) {
                return Err(LqrError::NotPositive {
                    what: format!("c{} (may be zero)", i + 1),
                    value: c,
                });
            }
        }
        Ok(())
    }

    pub fn mass_matrix(&self) -> Matrix3<f64> {
        Matrix3::from_diagonal(&Vector3::from(self.mass))
    }

    pub fn damping_matrix(&self) -> Matrix3<f64> {
        storey_matrix(&self.damping)
    }

    pub fn stiffness_matrix(&self) -> Matrix3<f64> {
        storey_matrix(&self.stiffness)
    }

    /// Undamped natural frequencies, Hz, ascending: the resonances the attenuation is read at.
    pub fn natural_frequencies(&self) -> [f64; FLOORS] {
        let s = Matrix3::from_diagonal(&Vector3::from(self.mass.map(|m| 1.0 / m.sqrt())));
        let sym = s * self.stiffness_matrix() * s;
        let mut w: Vec<f64> = sym
            .symmetric_eigenvalues()
            .iter()
            .map(|&l| l.max(0.0).sqrt() / (2.0 * std::f64::consts::PI))
            .collect();
        w.sort_by(f64::total_cmp);
        [w[0], w[1], w[2]]
    }

    /// The state-space model of eqs 17–19 with the state in units of `state_scale` metres.
    pub fn state_space(&self, state_scale: f64) -> Result<StateSpace, LqrError> {
        self.check()?;
        positive("state_scale", state_scale)?;
        let m_inv = self
            .mass_matrix()
            .try_inverse()
            .ok_or(LqrError::SingularMass)?;
        let mk = -(m_inv * self.stiffness_matrix());
        let mc = -(m_inv * self.damping_matrix());
        let mut a = StateMatrix::zeros();
        let mut c = SMatrix::<f64, FLOORS, STATES>::zeros();
        for i in 0..FLOORS {
            a[(i, FLOORS + i)] = 1.0;
            for j in 0..FLOORS {
                a[(FLOORS + i, j)] = mk[(i, j)];
                a[(FLOORS + i, FLOORS + j)] = mc[(i, j)];
                c[(i, j)] = mk[(i, j)];
                c[(i, FLOORS + j)] = mc[(i, j)];
            }
        }
        // φ = floor 1: a force of 1 N accelerates floor 1 by 1/m1 m/s², 1/(m1·scale) state
        // units.
        let mut b = StateVector::zeros();
        b[FLOORS] = m_inv[(0, 0)] / state_scale;
        let d = Vector3::new(m_inv[(0, 0)] / state_scale, 0.0, 0.0);
        Ok(StateSpace {
            a,
            b,
            c,
            d,
            state_scale,
        })
    }
}

/// `ẇ = A w + B (f_p − f_c)`, `z = C w + D (f_p − f_c)` with `w` and the accelerations `z` in
/// state units (eqs 17–19; B_p = B_c = B since both forces act on floor 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StateSpace {
    pub a: StateMatrix,
    pub b: StateVector,
    pub c: SMatrix<f64, FLOORS, STATES>,
    pub d: Vector3<f64>,
    /// Metres per state unit.
    pub state_scale: f64,
}

/// How the controller estimates the state from the measured accelerations.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Estimator {
    /// Integrate the accelerations twice (trapezoidal rule), each integral leaking with the
    /// corner frequency `highpass_hz`: the drift an offset or noise would make is removed, at
    /// the price of a phase lead `atan(f_c / f)` per integration near the first resonance.
    Integrate { highpass_hz: f64 },
    /// A steady-state Kalman observer on the model: `process_sd` is the sd (N) of a white force
    /// error on floor 1 per sample (the model's own error), `sensor_sd` the accelerometers'
    /// noise sd (m/s²).
    Kalman {
        process_sd: f64,
        sensor_sd: [f64; FLOORS],
    },
}

impl Estimator {
    pub fn name(&self) -> &'static str {
        match self {
            Estimator::Integrate { .. } => "integrate",
            Estimator::Kalman { .. } => "kalman",
        }
    }
}

#[derive(Clone, Debug)]
enum State {
    Integrate {
        /// Leak per sample, `exp(−2π f_c h)`.
        leak: f64,
        y: [f64; FLOORS],
        v: [f64; FLOORS],
        a_prev: [f64; FLOORS],
        started: bool,
    },
    Kalman(Box<Kalman>),
}

/// The discrete observer: the model's exact step map over the sample interval with the force
/// linear inside it (first-order hold) and the control force held, then the steady-state gain.
#[derive(Clone, Debug)]
struct Kalman {
    ad: StateMatrix,
    /// Response to the input at the start of the interval, held.
    g0: StateVector,
    /// Response to the input's slope inside the interval, times the interval.
    g1: StateVector,
    c: SMatrix<f64, FLOORS, STATES>,
    d: Vector3<f64>,
    l: SMatrix<f64, STATES, FLOORS>,
    w: StateVector,
    /// The last sample's force and control force (the prediction needs both ends).
    previous: Option<(f64, f64)>,
}

impl Kalman {
    fn new(
        model: &StateSpace,
        dt: f64,
        process_sd: f64,
        sensor_sd: [f64; FLOORS],
    ) -> Result<Self, LqrError> {
        positive("the Kalman process sd", process_sd)?;
        for (i, &s) in sensor_sd.iter().enumerate() {
            positive(&format!("the Kalman sensor sd of floor {}", i + 1), s)?;
        }
        // exp of [[A, B, 0], [0, 0, 1], [0, 0, 0]]·h gives the step map, the held-input
        // response and the ramp response in one go.
        let n = STATES + 2;
        let mut m = nalgebra::DMatrix::<f64>::zeros(n, n);
        for i in 0..STATES {
            for j in 0..STATES {
                m[(i, j)] = model.a[(i, j)] * dt;
            }
            m[(i, STATES)] = model.b[i] * dt;
        }
        m[(STATES, STATES + 1)] = dt;
        let e = m.exp();
        let mut ad = StateMatrix::zeros();
        let mut g0 = StateVector::zeros();
        let mut g1 = StateVector::zeros();
        for i in 0..STATES {
            for j in 0..STATES {
                ad[(i, j)] = e[(i, j)];
            }
            g0[i] = e[(i, STATES)];
            // The column multiplies the input's slope (per second); times 1/h it takes the
            // change over the interval.
            g1[i] = e[(i, STATES + 1)] / dt;
        }
        let qd = g0 * g0.transpose() * (process_sd * process_sd);
        let v = Matrix3::from_diagonal(&Vector3::from(
            sensor_sd.map(|s| (s / model.state_scale).powi(2)),
        ));
        let c = model.c;
        let mut p = qd;
        let mut l = SMatrix::<f64, STATES, FLOORS>::zeros();
        const MAX_ITERATIONS: usize = 200_000;
        let identity = StateMatrix::identity();
        let mut converged = false;
        for _ in 0..MAX_ITERATIONS {
            let predicted = ad * p * ad.transpose() + qd;
            let s = c * predicted * c.transpose() + v;
            let s_inv = s.try_inverse().ok_or(LqrError::SingularInnovation)?;
            let next = predicted * c.transpose() * s_inv;
            let ilc = identity - next * c;
            p = ilc * predicted * ilc.transpose() + next * v * next.transpose();
            p = (p + p.transpose()) * 0.5;
            let change = (next - l).norm();
            l = next;
            if change <= 1e-13 * l.norm() {
                converged = true;
                break;
            }
        }
        if !converged {
            return Err(LqrError::KalmanNotConverged(MAX_ITERATIONS));
        }
        Ok(Kalman {
            ad,
            g0,
            g1,
            c,
            d: model.d,
            l,
            w: StateVector::zeros(),
            previous: None,
        })
    }

    /// The estimate at this sample from the measured accelerations (state units), the force
    /// now and the control force that acted until now.
    fn update(&mut self, z: Vector3<f64>, force: f64, control_until_now: f64) -> StateVector {
        if let Some((force_prev, control_prev)) = self.previous {
            let u0 = force_prev - control_prev;
            self.w = self.ad * self.w + self.g0 * u0 + self.g1 * (force - force_prev);
        }
        let innovation = z - self.c * self.w - self.d * (force - control_until_now);
        self.w += self.l * innovation;
        self.w
    }
}

/// The run-time law `f_c = K ŵ`, one call per sample, as a digital controller runs it: the
/// command computed from the sample at `t_k` is applied from `t_{k+1}` (one sample of
/// computation delay). A co-simulation master gives every connection between FMUs that delay
/// anyway when the controller computes in its step, so the controller FMU, the master's block
/// and the synthetic structure's loop are the same system under any master.
#[derive(Clone, Debug)]
pub struct Controller {
    gain: [f64; STATES],
    state_scale: f64,
    dt: f64,
    state: State,
    /// The command acting over the interval that ends at the next sample.
    acting: f64,
    /// The command computed at the last sample, acting from the next one.
    pending: f64,
    estimate: StateVector,
}

impl Controller {
    /// A controller sampling every `dt` seconds with `gain` (N per state unit) on `model`.
    pub fn new(
        model: &StateSpace,
        gain: [f64; STATES],
        estimator: &Estimator,
        dt: f64,
    ) -> Result<Self, LqrError> {
        positive("the controller's sample interval", dt)?;
        if gain.iter().any(|g| !g.is_finite()) {
            return Err(LqrError::NonFiniteGain(gain));
        }
        let state = match *estimator {
            Estimator::Integrate { highpass_hz } => {
                positive("the integration's high-pass corner", highpass_hz)?;
                State::Integrate {
                    leak: (-2.0 * std::f64::consts::PI * highpass_hz * dt).exp(),
                    y: [0.0; FLOORS],
                    v: [0.0; FLOORS],
                    a_prev: [0.0; FLOORS],
                    started: false,
                }
            }
            Estimator::Kalman {
                process_sd,
                sensor_sd,
            } => State::Kalman(Box::new(Kalman::new(model, dt, process_sd, sensor_sd)?)),
        };
        Ok(Controller {
            gain,
            state_scale: model.state_scale,
            dt,
            state,
            acting: 0.0,
            pending: 0.0,
            estimate: StateVector::zeros(),
        })
    }

    /// Switch gains (gain scheduling); the estimator carries on.
    pub fn set_gain(&mut self, gain: [f64; STATES]) {
        self.gain = gain;
    }

    pub fn gain(&self) -> [f64; STATES] {
        self.gain
    }

    /// One sample: the accelerations measured now (m/s², before the new control force acts)
    /// and the excitation force now (N). Returns the new command (N), which acts from the next
    /// sample on; [`Controller::acting`] is the one that acts from now.
    pub fn step(&mut self, acc: [f64; FLOORS], force: f64) -> f64 {
        self.observe(acc, force);
        self.output()
    }

    /// The command acting from this sample to the next (the one computed a sample ago), N.
    pub fn acting(&self) -> f64 {
        self.acting
    }

    /// Update the state estimate with this sample's measurements (see [`Controller::step`]).
    pub fn observe(&mut self, acc: [f64; FLOORS], force: f64) {
        let scale = 1.0 / self.state_scale;
        let z = Vector3::from(acc.map(|a| a * scale));
        // Acting until now (the measurement's feedthrough), and from now to the next sample.
        let (until_now, from_now) = (self.acting, self.pending);
        let dt = self.dt;
        self.estimate = match &mut self.state {
            State::Integrate {
                leak,
                y,
                v,
                a_prev,
                started,
            } => {
                if *started {
                    for i in 0..FLOORS {
                        let v_next = *leak * v[i] + 0.5 * dt * (a_prev[i] + z[i]);
                        y[i] = *leak * y[i] + 0.5 * dt * (v[i] + v_next);
                        v[i] = v_next;
                    }
                }
                *started = true;
                *a_prev = [z[0], z[1], z[2]];
                StateVector::from_column_slice(&[y[0], y[1], y[2], v[0], v[1], v[2]])
            }
            State::Kalman(k) => {
                let w = k.update(z, force, until_now);
                k.previous = Some((force, from_now));
                w
            }
        };
    }

    /// The new command `K ŵ` from the current estimate and gain (N), acting from the next
    /// sample.
    pub fn output(&mut self) -> f64 {
        let u: f64 = self
            .gain
            .iter()
            .zip(self.estimate.iter())
            .map(|(g, w)| g * w)
            .sum();
        self.acting = self.pending;
        self.pending = u;
        u
    }

    /// The current state estimate in metres and metres per second.
    pub fn estimate_si(&self) -> [f64; STATES] {
        let mut out = [0.0; STATES];
        for (o, w) in out.iter_mut().zip(self.estimate.iter()) {
            *o = w * self.state_scale;
        }
        out
    }
}

/// What a [`Controller`] remembers between samples (its gain, the commands acting and pending,
/// the estimate and the estimator's memory), in plain numbers: the controller FMU serializes
/// its state with it and rebuilds the rest from its parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ControllerMemory {
    pub gain: [f64; STATES],
    pub acting: f64,
    pub pending: f64,
    pub estimate: [f64; STATES],
    pub estimator: EstimatorMemory,
}

/// The estimator's part of [`ControllerMemory`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum EstimatorMemory {
    Integrate {
        y: [f64; FLOORS],
        v: [f64; FLOORS],
        a_prev: [f64; FLOORS],
        started: bool,
    },
    Kalman {
        w: [f64; STATES],
        previous: Option<(f64, f64)>,
    },
}

impl Controller {
    /// The memory, to [`Controller::restore`] into a controller built with the same model,
    /// estimator and interval.
    pub fn memory(&self) -> ControllerMemory {
        let mut estimate = [0.0; STATES];
        estimate.copy_from_slice(self.estimate.as_slice());
        let estimator = match &self.state {
            State::Integrate {
                y,
                v,
                a_prev,
                started,
                ..
            } => EstimatorMemory::Integrate {
                y: *y,
                v: *v,
                a_prev: *a_prev,
                started: *started,
            },
            State::Kalman(k) => {
                let mut w = [0.0; STATES];
                w.copy_from_slice(k.w.as_slice());
                EstimatorMemory::Kalman {
                    w,
                    previous: k.previous,
                }
            }
        };
        ControllerMemory {
            gain: self.gain,
            acting: self.acting,
            pending: self.pending,
            estimate,
            estimator,
        }
    }

    /// Put back a memory taken with [`Controller::memory`]; false (and nothing changed) when
    /// it is of the other estimator.
    pub fn restore(&mut self, memory: &ControllerMemory) -> bool {
        match (&mut self.state, &memory.estimator) {
            (
                State::Integrate {
                    y,
                    v,
                    a_prev,
                    started,
                    ..
                },
                EstimatorMemory::Integrate {
                    y: my,
                    v: mv,
                    a_prev: ma,
                    started: ms,
                },
            ) => {
                *y = *my;
                *v = *mv;
                *a_prev = *ma;
                *started = *ms;
            }
            (State::Kalman(k), EstimatorMemory::Kalman { w, previous }) => {
                k.w = StateVector::from_column_slice(w);
                k.previous = *previous;
            }
            _ => return false,
        }
        self.gain = memory.gain;
        self.acting = memory.acting;
        self.pending = memory.pending;
        self.estimate = StateVector::from_column_slice(&memory.estimate);
        true
    }
}

/// Gain scheduling: the low gain while the structure is far from contact, the high gain when
/// the estimated drift of the watched storey, projected `lookahead` seconds ahead, comes within
/// `margin` (a fraction of the gap) of closing the gap — or when a corrector's latent variance
/// exceeds its threshold. Back to the low gain once neither has happened for `dwell` seconds
/// (hysteresis in time: the schedule does not chatter).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Schedule {
    /// The storey watched (1-based: storey 3 joins floors 2 and 3).
    pub storey: usize,
    /// The gap (m) and the side that closes it: 0 both, 1 positive drift, −1 negative drift.
    pub gap: f64,
    pub side: i32,
    pub margin: f64,
    pub lookahead: f64,
    pub dwell: f64,
    /// Latent variance threshold per floor (None: not used).
    pub variance_threshold: Option<[f64; FLOORS]>,
}

/// What made the schedule hold the high gain at a sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Triggers {
    /// The projected drift within the margin of the gap.
    pub drift: bool,
    /// A latent variance above its threshold.
    pub variance: bool,
}

/// The schedule's state.
#[derive(Clone, Debug)]
pub struct Scheduler {
    pub schedule: Schedule,
    high: bool,
    last_trigger: f64,
    last: Triggers,
}

impl Scheduler {
    pub fn new(schedule: Schedule) -> Result<Self, LqrError> {
        positive("the scheduled gap", schedule.gap)?;
        if !(0.0..1.0).contains(&schedule.margin) {
            return Err(LqrError::NotPositive {
                what: "the schedule's margin (a fraction of the gap in [0, 1))".into(),
                value: schedule.margin,
            });
        }
        if !(schedule.lookahead >= 0.0 && schedule.dwell >= 0.0) {
            return Err(LqrError::NotPositive {
                what: "the schedule's look-ahead and dwell (s, may be zero)".into(),
                value: schedule.lookahead.min(schedule.dwell),
            });
        }
        if !(1..=FLOORS).contains(&schedule.storey) {
            return Err(LqrError::NotPositive {
                what: "the scheduled storey (1..3)".into(),
                value: schedule.storey as f64,
            });
        }
        Ok(Scheduler {
            schedule,
            high: false,
            last_trigger: f64::NEG_INFINITY,
            last: Triggers::default(),
        })
    }

    pub fn high(&self) -> bool {
        self.high
    }

    /// What fired at the last decision.
    pub fn triggers(&self) -> Triggers {
        self.last
    }

    /// Decide at time `t` from the state estimate (SI) and, when the twin has a corrector, the
    /// latent variances. Returns whether the high gain is on.
    pub fn decide(
        &mut self,
        t: f64,
        estimate: &[f64; STATES],
        latent_var: Option<[f64; FLOORS]>,
    ) -> bool {
        let s = self.schedule.storey - 1;
        let drift = |x: &[f64]| x[s] - if s == 0 { 0.0 } else { x[s - 1] };
        let d = drift(&estimate[..FLOORS]) + self.schedule.lookahead * drift(&estimate[FLOORS..]);
        let near = (1.0 - self.schedule.margin) * self.schedule.gap;
        let closing = match self.schedule.side {
            1 => d > near,
            -1 => d < -near,
            _ => d.abs() > near,
        };
        let uncertain = match (self.schedule.variance_threshold, latent_var) {
            (Some(th), Some(v)) => v.iter().zip(th.iter()).any(|(v, th)| v > th),
            _ => false,
        };
        self.last = Triggers {
            drift: closing,
            variance: uncertain,
        };
        if closing || uncertain {
            self.last_trigger = t;
            self.high = true;
        } else if self.high && t - self.last_trigger >= self.schedule.dwell {
            self.high = false;
        }
        self.high
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame() -> ShearMatrices {
        ShearMatrices {
            mass: [5.2; 3],
            damping: [0.5; 3],
            stiffness: [4021.0; 3],
        }
    }

    /// The natural frequencies of three equal storeys: 2√(k/m)·sin((2i−1)π/14) rad/s.
    #[test]
    fn natural_frequencies_of_a_uniform_frame() {
        let f = frame().natural_frequencies();
        let w0 = (4021.0f64 / 5.2).sqrt();
        for (i, fi) in f.iter().enumerate() {
            let expected = 2.0 * w0 * ((2 * i + 1) as f64 * std::f64::consts::PI / 14.0).sin()
                / (2.0 * std::f64::consts::PI);
            assert!(
                (fi - expected).abs() < 1e-9 * expected,
                "{fi} vs {expected}"
            );
        }
    }

    /// A in millimetres equals A in metres; B scales with 1/state_scale.
    #[test]
    fn state_units_scale_b_not_a() {
        let m = frame().state_space(1.0).expect("valid");
        let mm = frame().state_space(1e-3).expect("valid");
        assert_eq!(m.a, mm.a);
        assert!((mm.b[3] - 1000.0 * m.b[3]).abs() < 1e-12);
        assert!((m.b[3] - 1.0 / 5.2).abs() < 1e-15);
        // The accelerations of a static displacement are −M⁻¹K y.
        let w = StateVector::from_column_slice(&[1e-3, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let z = m.c * w;
        assert!((z[0] + 2.0 * 4021.0 * 1e-3 / 5.2).abs() < 1e-12);
        assert!((z[1] - 4021.0 * 1e-3 / 5.2).abs() < 1e-12);
    }

    #[test]
    fn bad_parameters_are_refused() {
        let mut bad = frame();
        bad.mass[1] = 0.0;
        assert!(bad.state_space(1.0).is_err());
        bad = frame();
        bad.stiffness[2] = f64::NAN;
        assert!(bad.state_space(1.0).is_err());
        let ok = frame().state_space(1.0).expect("valid");
        let integrate = Estimator::Integrate { highpass_hz: 0.2 };
        assert!(Controller::new(&ok, [f64::NAN; 6], &integrate, 1e-3).is_err());
        assert!(Controller::new(&ok, [0.0; 6], &integrate, 0.0).is_err());
        let kalman = Estimator::Kalman {
            process_sd: 0.1,
            sensor_sd: [0.01, -1.0, 0.01],
        };
        assert!(Controller::new(&ok, [0.0; 6], &kalman, 1e-3).is_err());
    }

    /// The integrating estimator recovers a sine's velocity and displacement well above its
    /// corner frequency, to the leak's own error.
    #[test]
    fn integration_recovers_velocity_and_displacement_of_a_resonance() {
        let model = frame().state_space(1.0).expect("valid");
        let dt = 1.0 / 1000.0;
        let f = 5.0;
        let w = 2.0 * std::f64::consts::PI * f;
        let mut c = Controller::new(
            &model,
            [0.0; 6],
            &Estimator::Integrate { highpass_hz: 0.1 },
            dt,
        )
        .expect("valid");
        // From rest, a = sin(wt) integrates to v = (1 − cos wt)/w and a ramp in y; the leak
        // forgets those offsets, leaving v = −cos(wt)/w and y = −sin(wt)/w².
        let mut worst = 0.0f64;
        for k in 0..45_000 {
            let t = k as f64 * dt;
            let a = (w * t).sin();
            c.step([a, 0.0, 0.0], 0.0);
            if t > 35.0 {
                let e = c.estimate_si();
                let (y, v) = (-(w * t).sin() / (w * w), -(w * t).cos() / w);
                worst = worst
                    .max((e[0] - y).abs() * w * w)
                    .max((e[3] - v).abs() * w);
            }
        }
        // Each leaky integration errs by f_c/|f + j f_c| ≈ 0.02 at 5 Hz: 0.04 for y.
        assert!(worst < 0.045, "relative error {worst}");
    }

    /// The Kalman observer converges to the true state of the model it runs on, from noisy
    /// accelerations.
    #[test]
    fn kalman_observer_tracks_the_model() {
        let sm = frame();
        let model = sm.state_space(1e-3).expect("valid");
        let dt = 1.0 / 409.6;
        let mut c = Controller::new(
            &model,
            [0.0; 6],
            &Estimator::Kalman {
                process_sd: 0.05,
                sensor_sd: [1e-3; 3],
            },
            dt,
        )
        .expect("valid");
        // The truth: the same model stepped exactly with a smooth force, held per interval.
        let mut m = nalgebra::DMatrix::<f64>::zeros(7, 7);
        for i in 0..6 {
            for j in 0..6 {
                m[(i, j)] = model.a[(i, j)] * dt;
            }
            m[(i, 6)] = model.b[i] * dt;
        }
        let e = m.exp();
        let mut w = StateVector::zeros();
        let mut worst = 0.0f64;
        let mut peak = 0.0f64;
        for k in 0..8000 {
            let t = k as f64 * dt;
            let force = (2.0 * std::f64::consts::PI * 3.0 * t).sin()
                + 0.5 * (2.0 * std::f64::consts::PI * 7.3 * t).sin();
            let z = model.c * w + model.d * force;
            let acc = [z[0] * 1e-3, z[1] * 1e-3, z[2] * 1e-3];
            c.step(acc, force);
            if t > 5.0 {
                let est = c.estimate_si();
                for i in 0..6 {
                    worst = worst.max((est[i] - w[i] * 1e-3).abs());
                    peak = peak.max((w[i] * 1e-3).abs());
                }
            }
            // Advance the truth with the force held (the observer assumes it linear: the
            // difference is the model error the process noise covers).
            let mut next = StateVector::zeros();
            for i in 0..6 {
                next[i] = (0..6).map(|j| e[(i, j)] * w[j]).sum::<f64>() + e[(i, 6)] * force;
            }
            w = next;
        }
        assert!(worst < 0.05 * peak, "worst {worst} of peak {peak}");
    }

    #[test]
    fn schedule_switches_up_near_the_gap_and_back_after_the_dwell() {
        let mut s = Scheduler::new(Schedule {
            storey: 3,
            gap: 5e-4,
            side: -1,
            margin: 0.3,
            lookahead: 0.0,
            dwell: 0.5,
            variance_threshold: None,
        })
        .expect("valid");
        let at = |drift: f64| [0.0, 0.0, drift, 0.0, 0.0, 0.0];
        assert!(!s.decide(0.0, &at(-3e-4), None), "far from the gap");
        assert!(
            !s.decide(0.1, &at(4e-4), None),
            "the positive side does not close it"
        );
        assert!(s.decide(0.2, &at(-4e-4), None), "within 30 % of closing");
        assert!(s.decide(0.5, &at(0.0), None), "held during the dwell");
        assert!(!s.decide(0.71, &at(0.0), None), "released after the dwell");
        assert!(Scheduler::new(Schedule {
            margin: 1.5,
            ..s.schedule.clone()
        })
        .is_err());
    }
}
