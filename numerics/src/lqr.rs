//! The LQR controller's run-time law (the reference paper's section 6, eqs 16–22) for a linear
//! model of any size: `f_c = K ŵ`, with the state `ŵ` estimated from the measured accelerations,
//! either by integrating them with drift removal (as the paper does) or by a steady-state Kalman
//! observer on the model.
//!
//! No building lives here: the model's matrices come from the caller (the shear building's from
//! `structure::Structure::state_space` and `force_input`). The state is `w = [y; ẏ]` of `n`
//! degrees of freedom, `2n` states; the accelerometers read `n` absolute accelerations.
//!
//! The same code runs as a block of the orchestrator's master and inside the controller FMU, so
//! a controlled system gives the same numbers in any FMI host.
//!
//! Units: physical quantities in SI (m, N, kg); the state may be expressed in other units
//! through `state_scale` (metres per state unit: 1e-3 for the paper's millimetres), and then the
//! gain is in newtons per state unit.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Errors of the controller's set-up.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum LqrError {
    #[error("{what} must be finite and positive, got {value}")]
    NotPositive { what: String, value: f64 },
    #[error("the gain has a non-finite entry: {0:?}")]
    NonFiniteGain(Vec<f64>),
    #[error("{what} has {got} entries; the model needs {expected}")]
    Dimension {
        what: String,
        got: usize,
        expected: usize,
    },
    #[error("the Kalman observer's covariance did not settle in {0} iterations")]
    KalmanNotConverged(usize),
    #[error("the Kalman observer's innovation covariance is singular")]
    SingularInnovation,
    /// Eigenvalues of A (1/s, `[re, im]`) that no measurement sees: the state cannot be
    /// estimated from these measurements.
    #[error("the state is not observable from the measurements: no measurement sees the motion at eigenvalue(s) {}", .0.iter().map(|e| format!("{:.4}{:+.4}i", e[0], e[1])).collect::<Vec<_>>().join(", "))]
    Unobservable(Vec<[f64; 2]>),
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

fn dimension(what: &str, got: usize, expected: usize) -> Result<(), LqrError> {
    if got == expected {
        Ok(())
    } else {
        Err(LqrError::Dimension {
            what: what.to_owned(),
            got,
            expected,
        })
    }
}

/// `ẇ = A w + B_e u_e − B f_c`, `z = C w + D_e u_e − D f_c`: the state `w` (`n` displacements,
/// then `n` velocities) and the accelerations `z` in state units, `u_e` the excitation (known to
/// the Kalman observer: a force in N, or a ground acceleration in m/s²), `f_c` the control force
/// (N) of the actuator (eqs 17–19; the paper's B_p = B_c, shaker and actuator both on floor 1).
#[derive(Clone, Debug, PartialEq)]
pub struct StateSpace {
    pub a: DMatrix<f64>,
    /// The actuator's column, state units per N.
    pub b: DVector<f64>,
    pub c: DMatrix<f64>,
    /// The actuator's feedthrough into the accelerations.
    pub d: DVector<f64>,
    /// The excitation's column and feedthrough.
    pub excitation_b: DVector<f64>,
    pub excitation_d: DVector<f64>,
    /// Metres per state unit.
    pub state_scale: f64,
    /// What each measurement reads beyond the state's own motion per unit of excitation, where
    /// the state is relative to a moving ground: 1 for an accelerometer under ground motion (it
    /// reads `ÿ + a_g`), else 0. The integrating estimator removes it before integrating.
    pub ground_in_reading: DVector<f64>,
}

/// Relative tolerance of [`StateSpace::unobservable`]: the smallest singular value of
/// `[A − λI; C]` (C's rows scaled to unit norm) against the norm of A.
pub const OBSERVABILITY_TOLERANCE: f64 = 1e-9;

impl StateSpace {
    /// The model in state units of `state_scale` metres from one in SI (`ẋ = A x + B_e u_e +
    /// B f`, accelerations `C x + D_e u_e + D f`, `x` in m and m/s): A and C stay (a state and
    /// its accelerations scale alike), the input columns are divided by the scale.
    pub fn from_si(
        a: &DMatrix<f64>,
        c: &DMatrix<f64>,
        (excitation_b, excitation_d): (&DVector<f64>, &DVector<f64>),
        (actuator_b, actuator_d): (&DVector<f64>, &DVector<f64>),
        state_scale: f64,
    ) -> Result<StateSpace, LqrError> {
        positive("state_scale", state_scale)?;
        let states = a.nrows();
        if states == 0 || states % 2 != 0 {
            return Err(LqrError::Dimension {
                what: "the state (displacements then velocities)".into(),
                got: states,
                expected: 2 * (states / 2).max(1),
            });
        }
        dimension("A's columns", a.ncols(), states)?;
        dimension("C's columns", c.ncols(), states)?;
        dimension("the excitation's column", excitation_b.len(), states)?;
        dimension("the actuator's column", actuator_b.len(), states)?;
        dimension(
            "the excitation's feedthrough",
            excitation_d.len(),
            c.nrows(),
        )?;
        dimension("the actuator's feedthrough", actuator_d.len(), c.nrows())?;
        let all = a
            .iter()
            .chain(c.iter())
            .chain(excitation_b.iter())
            .chain(excitation_d.iter())
            .chain(actuator_b.iter())
            .chain(actuator_d.iter());
        if let Some(&bad) = all.into_iter().find(|x| !x.is_finite()) {
            return Err(LqrError::NotPositive {
                what: "every entry of the model (finite)".into(),
                value: bad,
            });
        }
        Ok(StateSpace {
            a: a.clone(),
            b: actuator_b / state_scale,
            c: c.clone(),
            d: actuator_d / state_scale,
            excitation_b: excitation_b / state_scale,
            excitation_d: excitation_d / state_scale,
            state_scale,
            ground_in_reading: DVector::zeros(c.nrows()),
        })
    }

    /// The same model with `ground` as [`StateSpace::ground_in_reading`] (one per measurement).
    pub fn with_ground_in_reading(mut self, ground: DVector<f64>) -> Result<Self, LqrError> {
        dimension(
            "the ground's part of the readings",
            ground.len(),
            self.c.nrows(),
        )?;
        self.ground_in_reading = ground;
        Ok(self)
    }

    /// The eigenvalues of A whose motion no measurement sees (the Popov–Belevitch–Hautus
    /// test: `[A − λI; C]` loses rank at λ), `[re, im]` in 1/s; empty when the state is
    /// observable from the measurements. C's rows are scaled to unit norm first (the
    /// measurements may be of different quantities), and rank is judged against
    /// [`OBSERVABILITY_TOLERANCE`] times the norm of A.
    pub fn unobservable(&self) -> Vec<[f64; 2]> {
        use nalgebra::Complex;
        let states = self.states();
        let rows = self.c.nrows();
        if rows == 0 {
            let mut all: Vec<[f64; 2]> = self
                .a
                .complex_eigenvalues()
                .iter()
                .map(|l| [l.re, l.im])
                .collect();
            all.sort_by(|x, y| x[1].total_cmp(&y[1]));
            return all;
        }
        let scale = self.a.norm().max(f64::MIN_POSITIVE);
        let mut c = self.c.clone();
        for mut row in c.row_iter_mut() {
            let norm = row.norm();
            if norm > 0.0 {
                row /= norm;
            }
        }
        let mut out = Vec::new();
        for lambda in self.a.complex_eigenvalues().iter() {
            let m = DMatrix::<Complex<f64>>::from_fn(states + rows, states, |i, j| {
                if i < states {
                    let diagonal = if i == j {
                        *lambda
                    } else {
                        Complex::new(0.0, 0.0)
                    };
                    Complex::new(self.a[(i, j)], 0.0) - diagonal
                } else {
                    Complex::new(c[(i - states, j)] * scale, 0.0)
                }
            });
            let smallest = m
                .singular_values()
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min);
            if smallest <= OBSERVABILITY_TOLERANCE * scale {
                out.push([lambda.re, lambda.im]);
            }
        }
        out
    }

    /// States: `2n`.
    pub fn states(&self) -> usize {
        self.a.nrows()
    }

    /// Degrees of freedom (floors): `n`.
    pub fn floors(&self) -> usize {
        self.a.nrows() / 2
    }

    /// Whether the actuator acts where the excitation does (the paper's rig): then the two
    /// enter the model as their difference.
    fn actuator_at_excitation(&self) -> bool {
        self.b == self.excitation_b && self.d == self.excitation_d
    }
}

/// How the controller estimates the state from the measured accelerations.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Estimator {
    /// Integrate the accelerations twice (trapezoidal rule), each integral leaking with the
    /// corner frequency `highpass_hz`: the drift an offset or noise would make is removed, at
    /// the price of a phase lead `atan(f_c / f)` per integration near the first resonance.
    Integrate { highpass_hz: f64 },
    /// A steady-state Kalman observer on the model: `process_sd` is the sd of a white error of
    /// the excitation per sample (N for a force: the model's own error), `sensor_sd` the
    /// accelerometers' noise sd (m/s²), one per measured acceleration.
    Kalman {
        process_sd: f64,
        sensor_sd: Vec<f64>,
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
        /// The ground's part of each reading per unit of excitation (removed before integrating).
        ground: Vec<f64>,
        y: Vec<f64>,
        v: Vec<f64>,
        a_prev: Vec<f64>,
        started: bool,
    },
    Kalman(Box<Kalman>),
}

/// The discrete observer: the model's exact step map over the sample interval with the
/// excitation linear inside it (first-order hold) and the control force held, then the
/// steady-state gain.
#[derive(Clone, Debug)]
struct Kalman {
    ad: DMatrix<f64>,
    /// Response to the excitation at the start of the interval, held.
    g0: DVector<f64>,
    /// Response to the excitation's slope inside the interval, times the interval.
    g1: DVector<f64>,
    /// Response to the control force, held; None when the actuator acts where the excitation
    /// does (then `g0` serves both, on their difference).
    g0_control: Option<DVector<f64>>,
    c: DMatrix<f64>,
    d: DVector<f64>,
    /// The control force's feedthrough, when the actuator is not at the excitation.
    d_control: Option<DVector<f64>>,
    l: DMatrix<f64>,
    w: DVector<f64>,
    /// The last sample's excitation and control force (the prediction needs both ends).
    previous: Option<(f64, f64)>,
}

/// `exp([[A, b, 0], [0, 0, 1], [0, 0, 0]]·h)`: the step map, the held-input response and the
/// ramp response (per second of slope) of input column `b`, in one go.
fn step_map(a: &DMatrix<f64>, b: &DVector<f64>, dt: f64) -> DMatrix<f64> {
    let states = a.nrows();
    let n = states + 2;
    let mut m = DMatrix::<f64>::zeros(n, n);
    for i in 0..states {
        for j in 0..states {
            m[(i, j)] = a[(i, j)] * dt;
        }
        m[(i, states)] = b[i] * dt;
    }
    m[(states, states + 1)] = dt;
    m.exp()
}

impl Kalman {
    fn new(
        model: &StateSpace,
        dt: f64,
        process_sd: f64,
        sensor_sd: &[f64],
    ) -> Result<Self, LqrError> {
        positive("the Kalman process sd", process_sd)?;
        let unobservable = model.unobservable();
        if !unobservable.is_empty() {
            return Err(LqrError::Unobservable(unobservable));
        }
        let measured = model.c.nrows();
        dimension("the Kalman sensor sd", sensor_sd.len(), measured)?;
        for (i, &s) in sensor_sd.iter().enumerate() {
            positive(&format!("the Kalman sensor sd of measurement {}", i + 1), s)?;
        }
        let states = model.states();
        let e = step_map(&model.a, &model.excitation_b, dt);
        let ad = e.view((0, 0), (states, states)).into_owned();
        let g0 = e.view((0, states), (states, 1)).column(0).into_owned();
        // The column multiplies the input's slope (per second); times 1/h it takes the change
        // over the interval.
        let g1 = e.view((0, states + 1), (states, 1)).column(0) / dt;
        let (g0_control, d_control) = if model.actuator_at_excitation() {
            (None, None)
        } else {
            let e = step_map(&model.a, &model.b, dt);
            (
                Some(e.view((0, states), (states, 1)).column(0).into_owned()),
                Some(model.d.clone()),
            )
        };
        let qd = &g0 * g0.transpose() * (process_sd * process_sd);
        let v = DMatrix::from_diagonal(&DVector::from_iterator(
            measured,
            sensor_sd.iter().map(|s| (s / model.state_scale).powi(2)),
        ));
        let c = model.c.clone();
        let mut p = qd.clone();
        let mut l = DMatrix::<f64>::zeros(states, measured);
        const MAX_ITERATIONS: usize = 200_000;
        let identity = DMatrix::<f64>::identity(states, states);
        let mut converged = false;
        for _ in 0..MAX_ITERATIONS {
            let predicted = &ad * &p * ad.transpose() + &qd;
            let s = &c * &predicted * c.transpose() + &v;
            let s_inv = s.try_inverse().ok_or(LqrError::SingularInnovation)?;
            let next = &predicted * c.transpose() * s_inv;
            let ilc = &identity - &next * &c;
            p = &ilc * &predicted * ilc.transpose() + &next * &v * next.transpose();
            p = (&p + p.transpose()) * 0.5;
            let change = (&next - &l).norm();
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
            g0_control,
            c,
            d: model.excitation_d.clone(),
            d_control,
            l,
            w: DVector::zeros(states),
            previous: None,
        })
    }

    /// The estimate at this sample from the measured accelerations (state units), the
    /// excitation now and the control force that acted until now.
    fn update(&mut self, z: DVector<f64>, force: f64, control_until_now: f64) -> DVector<f64> {
        if let Some((force_prev, control_prev)) = self.previous {
            self.w = match &self.g0_control {
                None => {
                    let u0 = force_prev - control_prev;
                    &self.ad * &self.w + &self.g0 * u0 + &self.g1 * (force - force_prev)
                }
                Some(g0_control) => {
                    &self.ad * &self.w + &self.g0 * force_prev - g0_control * control_prev
                        + &self.g1 * (force - force_prev)
                }
            };
        }
        let innovation = match &self.d_control {
            None => z - &self.c * &self.w - &self.d * (force - control_until_now),
            Some(d_control) => {
                z - &self.c * &self.w - &self.d * force + d_control * control_until_now
            }
        };
        self.w += &self.l * innovation;
        self.w.clone()
    }
}

/// The run-time law `f_c = K ŵ`, one call per sample, as a digital controller runs it: the
/// command computed from the sample at `t_k` is applied from `t_{k+1}` (one sample of
/// computation delay). A co-simulation master gives every connection between FMUs that delay
/// anyway when the controller computes in its step, so the controller FMU, the master's block
/// and the synthetic structure's loop are the same system under any master.
#[derive(Clone, Debug)]
pub struct Controller {
    gain: Vec<f64>,
    state_scale: f64,
    dt: f64,
    state: State,
    /// The command acting over the interval that ends at the next sample.
    acting: f64,
    /// The command computed at the last sample, acting from the next one.
    pending: f64,
    estimate: DVector<f64>,
}

impl Controller {
    /// A controller sampling every `dt` seconds with `gain` (N per state unit, one per state)
    /// on `model`.
    pub fn new(
        model: &StateSpace,
        gain: &[f64],
        estimator: &Estimator,
        dt: f64,
    ) -> Result<Self, LqrError> {
        positive("the controller's sample interval", dt)?;
        dimension("the gain", gain.len(), model.states())?;
        if gain.iter().any(|g| !g.is_finite()) {
            return Err(LqrError::NonFiniteGain(gain.to_vec()));
        }
        let floors = model.floors();
        let state = match estimator {
            Estimator::Integrate { highpass_hz } => {
                positive("the integration's high-pass corner", *highpass_hz)?;
                // Integrating needs every floor's acceleration.
                dimension("the measured accelerations", model.c.nrows(), floors)?;
                State::Integrate {
                    leak: (-2.0 * std::f64::consts::PI * highpass_hz * dt).exp(),
                    ground: model.ground_in_reading.iter().copied().collect(),
                    y: vec![0.0; floors],
                    v: vec![0.0; floors],
                    a_prev: vec![0.0; floors],
                    started: false,
                }
            }
            Estimator::Kalman {
                process_sd,
                sensor_sd,
            } => State::Kalman(Box::new(Kalman::new(model, dt, *process_sd, sensor_sd)?)),
        };
        Ok(Controller {
            gain: gain.to_vec(),
            state_scale: model.state_scale,
            dt,
            state,
            acting: 0.0,
            pending: 0.0,
            estimate: DVector::zeros(model.states()),
        })
    }

    /// Switch gains (gain scheduling); the estimator carries on. A gain of another length than
    /// the state is refused.
    pub fn set_gain(&mut self, gain: &[f64]) -> Result<(), LqrError> {
        dimension("the gain", gain.len(), self.gain.len())?;
        self.gain.copy_from_slice(gain);
        Ok(())
    }

    pub fn gain(&self) -> &[f64] {
        &self.gain
    }

    /// How many accelerations [`Controller::step`] takes.
    pub fn measurements(&self) -> usize {
        match &self.state {
            State::Integrate { y, .. } => y.len(),
            State::Kalman(k) => k.c.nrows(),
        }
    }

    /// One sample: the accelerations measured now (m/s², before the new control force acts)
    /// and the excitation now (N, or m/s² for ground motion). Returns the new command (N),
    /// which acts from the next sample on; [`Controller::acting`] is the one that acts from
    /// now.
    pub fn step(&mut self, acc: &[f64], force: f64) -> Result<f64, LqrError> {
        self.observe(acc, force)?;
        Ok(self.output())
    }

    /// The command acting from this sample to the next (the one computed a sample ago), N.
    pub fn acting(&self) -> f64 {
        self.acting
    }

    /// Update the state estimate with this sample's measurements (see [`Controller::step`]).
    pub fn observe(&mut self, acc: &[f64], force: f64) -> Result<(), LqrError> {
        dimension("the measured accelerations", acc.len(), self.measurements())?;
        let scale = 1.0 / self.state_scale;
        let z = DVector::from_iterator(acc.len(), acc.iter().map(|a| a * scale));
        // Acting until now (the measurement's feedthrough), and from now to the next sample.
        let (until_now, from_now) = (self.acting, self.pending);
        let dt = self.dt;
        self.estimate = match &mut self.state {
            State::Integrate {
                leak,
                ground,
                y,
                v,
                a_prev,
                started,
            } => {
                let z = DVector::from_iterator(
                    z.len(),
                    z.iter()
                        .zip(ground.iter())
                        .map(|(z, g)| z - g * force * scale),
                );
                if *started {
                    for i in 0..y.len() {
                        let v_next = *leak * v[i] + 0.5 * dt * (a_prev[i] + z[i]);
                        y[i] = *leak * y[i] + 0.5 * dt * (v[i] + v_next);
                        v[i] = v_next;
                    }
                }
                *started = true;
                a_prev.copy_from_slice(z.as_slice());
                DVector::from_iterator(2 * y.len(), y.iter().chain(v.iter()).copied())
            }
            State::Kalman(k) => {
                let w = k.update(z, force, until_now);
                k.previous = Some((force, from_now));
                w
            }
        };
        Ok(())
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
    pub fn estimate_si(&self) -> Vec<f64> {
        self.estimate.iter().map(|w| w * self.state_scale).collect()
    }
}

/// What a [`Controller`] remembers between samples (its gain, the commands acting and pending,
/// the estimate and the estimator's memory), in plain numbers: the controller FMU serializes
/// its state with it and rebuilds the rest from its parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ControllerMemory {
    pub gain: Vec<f64>,
    pub acting: f64,
    pub pending: f64,
    pub estimate: Vec<f64>,
    pub estimator: EstimatorMemory,
}

/// The estimator's part of [`ControllerMemory`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum EstimatorMemory {
    Integrate {
        y: Vec<f64>,
        v: Vec<f64>,
        a_prev: Vec<f64>,
        started: bool,
    },
    Kalman {
        w: Vec<f64>,
        previous: Option<(f64, f64)>,
    },
}

impl Controller {
    /// The memory, to [`Controller::restore`] into a controller built with the same model,
    /// estimator and interval.
    pub fn memory(&self) -> ControllerMemory {
        let estimator = match &self.state {
            State::Integrate {
                y,
                v,
                a_prev,
                started,
                ..
            } => EstimatorMemory::Integrate {
                y: y.clone(),
                v: v.clone(),
                a_prev: a_prev.clone(),
                started: *started,
            },
            State::Kalman(k) => EstimatorMemory::Kalman {
                w: k.w.iter().copied().collect(),
                previous: k.previous,
            },
        };
        ControllerMemory {
            gain: self.gain.clone(),
            acting: self.acting,
            pending: self.pending,
            estimate: self.estimate.iter().copied().collect(),
            estimator,
        }
    }

    /// Put back a memory taken with [`Controller::memory`]; false (and nothing changed) when
    /// it is of the other estimator or of another size.
    pub fn restore(&mut self, memory: &ControllerMemory) -> bool {
        let states = self.estimate.len();
        if memory.gain.len() != states || memory.estimate.len() != states {
            return false;
        }
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
                if [my, mv, ma].iter().any(|m| m.len() != y.len()) {
                    return false;
                }
                y.copy_from_slice(my);
                v.copy_from_slice(mv);
                a_prev.copy_from_slice(ma);
                *started = *ms;
            }
            (State::Kalman(k), EstimatorMemory::Kalman { w, previous }) => {
                if w.len() != states {
                    return false;
                }
                k.w = DVector::from_column_slice(w);
                k.previous = *previous;
            }
            _ => return false,
        }
        self.gain.copy_from_slice(&memory.gain);
        self.acting = memory.acting;
        self.pending = memory.pending;
        self.estimate = DVector::from_column_slice(&memory.estimate);
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
    pub variance_threshold: Option<Vec<f64>>,
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
    /// The schedule of a structure of `floors` floors.
    pub fn new(schedule: Schedule, floors: usize) -> Result<Self, LqrError> {
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
        if !(1..=floors).contains(&schedule.storey) {
            return Err(LqrError::NotPositive {
                what: format!("the scheduled storey (1..{floors})"),
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

    /// Decide at time `t` from the state estimate (SI: displacements, then velocities) and,
    /// when the twin has a corrector, the latent variances. Returns whether the high gain is on.
    pub fn decide(&mut self, t: f64, estimate: &[f64], latent_var: Option<&[f64]>) -> bool {
        let floors = estimate.len() / 2;
        let s = self.schedule.storey - 1;
        let drift = |x: &[f64]| x[s] - if s == 0 { 0.0 } else { x[s - 1] };
        let d = drift(&estimate[..floors]) + self.schedule.lookahead * drift(&estimate[floors..]);
        let near = (1.0 - self.schedule.margin) * self.schedule.gap;
        let closing = match self.schedule.side {
            1 => d > near,
            -1 => d < -near,
            _ => d.abs() > near,
        };
        let uncertain = match (&self.schedule.variance_threshold, latent_var) {
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
mod tests;
