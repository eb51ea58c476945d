//! The scenario's ranges checked: its sampling, structure, channels, force, noise, effects and
//! changes, each refused naming the file and field.

use super::json::Loc;
use super::{
    in_band, ChangeHow, DampingSite, EffectSpec, ForceWindow, NoiseLevel, ParamKind, Scenario,
};
use crate::synth::Result;
use crate::synth::{GENERATOR_OVERSAMPLE, MAX_FINE_POINTS, MAX_OVERSAMPLE};
use ::structure::channel::Channel;
use ::structure::effects::Side;
use ::structure::{Excitation, MAX_STOREYS};

impl Scenario {
    /// Check the ranges; `origin` names the source (a file, or "scenario") in the errors.
    pub fn validate(&self, origin: &str) -> Result<()> {
        let at = Loc {
            origin,
            path: String::new(),
        };
        let n = self.check_sampling(&at)?;
        let n_storeys = self.check_structure(&at)?;
        let channels = self.check_channels(&at, n_storeys)?;
        self.check_force(&at, n)?;
        self.check_noise(&at, channels)?;
        self.check_effects(&at, n_storeys)?;
        self.check_changes(&at, n, n_storeys)
    }

    /// The sampling: a positive rate and duration, an oversampling in range, and a record of at
    /// least 2 samples that is not too long for the force's or the structure's fine grid.
    /// Returns the number of samples.
    pub(super) fn check_sampling(&self, at: &Loc) -> Result<usize> {
        positive(at.field("sample_rate"), self.sample_rate, true)?;
        positive(at.field("duration"), self.duration, true)?;
        if !(1..=MAX_OVERSAMPLE).contains(&self.oversample) {
            return Err(at.field("oversample").error(format!(
                "{} is outside [1, {MAX_OVERSAMPLE}]",
                self.oversample
            )));
        }
        let n = self.samples();
        if n < 2 {
            return Err(at.field("duration").error(format!(
                "{} s at {} Hz gives {n} samples; at least 2 are needed",
                self.duration, self.sample_rate
            )));
        }
        if n.saturating_mul(GENERATOR_OVERSAMPLE) > MAX_FINE_POINTS {
            return Err(at.field("duration").error(format!(
                "{:?} s at {:?} Hz is too long a record (at most {} samples)",
                self.duration,
                self.sample_rate,
                MAX_FINE_POINTS / GENERATOR_OVERSAMPLE
            )));
        }
        if n.saturating_mul(self.oversample as usize) > MAX_FINE_POINTS {
            return Err(at.field("oversample").error(format!(
                "{n} samples × {} fine steps is more than the {MAX_FINE_POINTS} fine points allowed",
                self.oversample
            )));
        }
        Ok(n)
    }

    /// The structure: 1 to [`MAX_STOREYS`] floors with a value of each parameter per storey in
    /// range, a forced floor the structure has, and under ground motion a valid spectrum and
    /// envelope. Returns the number of storeys.
    pub(super) fn check_structure(&self, at: &Loc) -> Result<usize> {
        let p = at.field("parameters");
        let n_storeys = self.storeys();
        if !(1..=MAX_STOREYS).contains(&n_storeys) {
            return Err(p.field("m").error(format!(
                "{n_storeys} floors; a structure has 1 to {MAX_STOREYS}"
            )));
        }
        for (name, values) in [("c", &self.damping), ("k", &self.stiffness)] {
            if values.len() != n_storeys {
                return Err(p.field(name).error(format!(
                    "{} values for {n_storeys} storeys (m has {n_storeys})",
                    values.len()
                )));
            }
        }
        for i in 0..n_storeys {
            positive(p.field("m").index(i), self.mass[i], true)?;
            positive(p.field("c").index(i), self.damping[i], false)?;
            positive(p.field("k").index(i), self.stiffness[i], false)?;
        }
        if let Excitation::Force { floor } = self.excitation {
            if !(1..=n_storeys).contains(&floor) {
                return Err(at.field("excitation").error(format!(
                    "force:{floor}: the structure has floors 1 to {n_storeys}"
                )));
            }
        }
        if self.excitation == Excitation::Base {
            let g = at.field("ground_motion");
            positive(g.field("soil_hz"), self.ground.soil_hz, true)?;
            positive(g.field("soil_damping"), self.ground.soil_damping, true)?;
            positive(g.field("rise_end"), self.ground.rise_end, true)?;
            positive(g.field("decay"), self.ground.decay, false)?;
            if !(self.ground.strong_end.is_finite()
                && self.ground.strong_end >= self.ground.rise_end)
            {
                return Err(g.field("strong_end").error(format!(
                    "{} s must be a finite time ≥ rise_end {} s",
                    self.ground.strong_end, self.ground.rise_end
                )));
            }
        }
        Ok(n_storeys)
    }

    /// The response channels: at least one, each a response of a floor the structure has, in a
    /// unit of its quantity, none twice. Returns how many there are.
    pub(super) fn check_channels(&self, at: &Loc, n_storeys: usize) -> Result<usize> {
        let channels = self.response_channels();
        if channels.is_empty() {
            return Err(at
                .field("channels")
                .error("is empty; give at least one response channel".into()));
        }
        for (i, (channel, unit)) in channels.iter().enumerate() {
            let at = at.field("channels").index(i);
            match channel {
                Channel::Response { floor, quantity } => {
                    if !(1..=n_storeys).contains(floor) {
                        return Err(at.error(format!(
                            "'{}': the structure has floors 1 to {n_storeys}",
                            channel.name()
                        )));
                    }
                    if unit.quantity() != *quantity {
                        return Err(at.error(format!(
                            "'{}' cannot be in {}",
                            channel.name(),
                            unit.symbol()
                        )));
                    }
                }
                _ => {
                    return Err(at.error(format!(
                        "'{}' is not a response (acc<i>, vel<i> or disp<i>); the excitation is always written",
                        channel.name()
                    )))
                }
            }
            if channels[..i].iter().any(|(c, _)| c == channel) {
                return Err(at.error(format!("'{}' is given twice", channel.name())));
            }
        }
        Ok(channels.len())
    }

    /// The force: its level, a band below the Nyquist frequency that holds at least one of the
    /// `n`-sample record's frequencies, and its windows.
    pub(super) fn check_force(&self, at: &Loc, n: usize) -> Result<()> {
        let f = at.field("force");
        positive(f.field("rms"), self.force.rms, false)?;
        positive(f.field("low_hz"), self.force.low_hz, false)?;
        let band = self.band_hz();
        let nyquist = 0.5 * self.sample_rate;
        positive(f.field("band_hz"), band, true)?;
        if band > nyquist * (1.0 + 1e-12) {
            return Err(f.field("band_hz").error(format!(
                "{band} Hz is above the Nyquist frequency {nyquist} Hz of the {} Hz sampling",
                self.sample_rate
            )));
        }
        let record = n as f64 / self.sample_rate;
        let bins = (1..=n * GENERATOR_OVERSAMPLE / 2)
            .filter(|&k| in_band(k as f64 / record, self.force.low_hz, band))
            .count();
        if bins == 0 {
            return Err(f.error(format!(
                "no frequency of the {record} s record (resolution {} Hz) lies strictly between low_hz {} and band_hz {band}",
                1.0 / record,
                self.force.low_hz
            )));
        }
        for (i, w) in self.force.windows.iter().enumerate() {
            check_window(f.field("windows").index(i), w)?;
        }
        Ok(())
    }

    /// The noise: one level or one per response channel (`channels` of them), each in range,
    /// and the force's fraction.
    pub(super) fn check_noise(&self, at: &Loc, channels: usize) -> Result<()> {
        let noise = at.field("noise");
        let (name, levels) = match &self.noise.level {
            NoiseLevel::Fraction(x) => ("fraction", x),
            NoiseLevel::Sd(x) => ("sd", x),
        };
        if levels.len() != 1 && levels.len() != channels {
            return Err(noise.field(name).error(format!(
                "{} values for {} response channels; give one value or one per channel",
                levels.len(),
                channels
            )));
        }
        for (i, &x) in levels.iter().enumerate() {
            positive(noise.field(name).index(i), x, false)?;
        }
        positive(
            noise.field("force_fraction"),
            self.noise.force_fraction,
            false,
        )
    }

    /// The effects: each at a site of the structure, its parameters in range, and at most one of
    /// a kind per location.
    pub(super) fn check_effects(&self, at: &Loc, n_storeys: usize) -> Result<()> {
        for (i, e) in self.effects.iter().enumerate() {
            let at = at.field("effects").index(i);
            check_effect(&at, e, n_storeys)?;
            check_library_parameters(&at, e)?;
            if let Some(j) = self.effects[..i].iter().position(|o| o.same_place(e)) {
                return Err(at.error(format!(
                    "{} {} is already given as effects[{j}]; one effect of a kind per location",
                    e.kind(),
                    e.describe_location()
                )));
            }
        }
        Ok(())
    }

    /// The changes: each of a parameter the structure has, inside the `n`-sample record, by a
    /// factor or to a value in range.
    pub(super) fn check_changes(&self, at: &Loc, n: usize, n_storeys: usize) -> Result<()> {
        let last = (n - 1) as f64 / self.sample_rate;
        for (i, c) in self.changes.iter().enumerate() {
            let at = at.field("changes").index(i);
            if c.parameter.index >= n_storeys {
                return Err(at.field("parameter").error(format!(
                    "{} is not a parameter of the {n_storeys}-storey structure",
                    c.parameter.name()
                )));
            }
            if !(c.at.is_finite() && c.at >= 0.0 && c.at <= last) {
                return Err(at
                    .field("at")
                    .error(format!("{} s is outside the record [0, {last}] s", c.at)));
            }
            let strictly = c.parameter.kind == ParamKind::Mass;
            match c.how {
                ChangeHow::Factor(x) => positive(at.field("factor"), x, strictly)?,
                ChangeHow::Value(x) => positive(at.field("value"), x, strictly)?,
            }
        }
        Ok(())
    }
}

/// `x` is finite and > 0 (`strictly`) or ≥ 0; refused at `loc` otherwise.
pub(super) fn positive(loc: Loc, x: f64, strictly: bool) -> Result<()> {
    let ok = x.is_finite() && if strictly { x > 0.0 } else { x >= 0.0 };
    if ok {
        Ok(())
    } else {
        Err(loc.error(format!(
            "{x} must be a finite number {} 0",
            if strictly { ">" } else { "≥" }
        )))
    }
}

/// A force window (at `at`): finite numbers, an end after its start, a gain and a ramp in
/// range, the ramp no longer than the window.
pub(super) fn check_window(at: Loc, w: &ForceWindow) -> Result<()> {
    for (name, x) in [
        ("start", w.start),
        ("end", w.end),
        ("gain", w.gain),
        ("ramp", w.ramp),
    ] {
        if !x.is_finite() {
            return Err(at.field(name).error(format!("{x} is not a finite number")));
        }
    }
    if w.end <= w.start {
        return Err(at
            .field("end")
            .error(format!("{} must be after start {}", w.end, w.start)));
    }
    positive(at.field("gain"), w.gain, false)?;
    positive(at.field("ramp"), w.ramp, false)?;
    if w.ramp > w.end - w.start {
        return Err(at.field("ramp").error(format!(
            "{} s is longer than the window ({} s); the ramps are centred on its edges",
            w.ramp,
            w.end - w.start
        )));
    }
    Ok(())
}

/// An effect (at `at`) where the `n_storeys`-storey structure has a site for its kind, with a
/// valid side (contact) or parameters (hysteresis, quadratic damping).
pub(super) fn check_effect(at: &Loc, e: &EffectSpec, n_storeys: usize) -> Result<()> {
    match *e {
        EffectSpec::Contact { lower, side, .. } => {
            if lower >= n_storeys {
                return Err(at.field("location").error(format!(
                    "[{lower}, {}] is not a storey of the {n_storeys}-storey structure",
                    lower + 1
                )));
            }
            if Side::from_code(side).is_none() {
                return Err(at.field("side").error(format!("{side} is not -1, 0 or 1")));
            }
        }
        EffectSpec::Cubic { storey, .. } => {
            if !(1..=n_storeys).contains(&storey) {
                return Err(at
                    .field("location")
                    .error(format!("storey {storey} is not one of 1..{n_storeys}")));
            }
        }
        EffectSpec::Friction { floor, .. } => {
            if !(1..=n_storeys).contains(&floor) {
                return Err(at
                    .field("location")
                    .error(format!("floor {floor} is not one of 1..{n_storeys}")));
            }
        }
        EffectSpec::Hysteresis { .. } => check_hysteresis(at, e, n_storeys)?,
        EffectSpec::QuadraticDamping { site, coefficient } => {
            match site {
                DampingSite::Storey(s) if !(1..=n_storeys).contains(&s) => {
                    return Err(at
                        .field("location")
                        .error(format!("storey {s} is not one of 1..{n_storeys}")))
                }
                DampingSite::Floor(f) if !(1..=n_storeys).contains(&f) => {
                    return Err(at
                        .field("floor")
                        .error(format!("floor {f} is not one of 1..{n_storeys}")))
                }
                _ => {}
            }
            positive(at.field("coefficient"), coefficient, true)?;
        }
    }
    Ok(())
}

/// A hysteresis effect (at `at`): a storey of the `n_storeys`, positive stiffness and yield
/// drift, finite β and γ with β + γ > 0, an exponent ≥ 1.
pub(super) fn check_hysteresis(at: &Loc, e: &EffectSpec, n_storeys: usize) -> Result<()> {
    let EffectSpec::Hysteresis {
        storey,
        stiffness,
        yield_drift,
        beta,
        gamma,
        exponent,
    } = *e
    else {
        return Ok(());
    };
    if !(1..=n_storeys).contains(&storey) {
        return Err(at
            .field("location")
            .error(format!("storey {storey} is not one of 1..{n_storeys}")));
    }
    positive(at.field("stiffness"), stiffness, true)?;
    positive(at.field("yield"), yield_drift, true)?;
    for (name, x) in [("beta", beta), ("gamma", gamma)] {
        if !x.is_finite() {
            return Err(at.field(name).error(format!("{x} is not a finite number")));
        }
    }
    if beta + gamma <= 0.0 {
        return Err(at.field("gamma").error(format!(
            "beta + gamma = {beta} + {gamma} must be > 0 (|z| saturates at yield · (1/(beta + gamma))^(1/exponent))"
        )));
    }
    if !(exponent.is_finite() && exponent >= 1.0) {
        return Err(at
            .field("exponent")
            .error(format!("{exponent} must be a finite number ≥ 1")));
    }
    Ok(())
}

/// A library effect's parameters (at `at`): the ranges the FMU accepts.
pub(super) fn check_library_parameters(at: &Loc, e: &EffectSpec) -> Result<()> {
    if let Some((kind, _, law)) = e.library() {
        for (p, x) in kind.real_params().iter().zip(law.reals()) {
            let at = at.field(p.suffix);
            if p.min == 0.0 {
                positive(at, x, p.strictly)?;
            } else if !x.is_finite() {
                return Err(at.error(format!("{x} is not a finite number")));
            } else if x < p.min || (p.strictly && x == p.min) {
                return Err(at.error(format!(
                    "{x} must be {} {}",
                    if p.strictly { ">" } else { "≥" },
                    p.min
                )));
            }
        }
    }
    Ok(())
}
