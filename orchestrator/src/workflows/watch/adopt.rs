//! A failing window diagnosed in the background and, on its verdict, a twin adopted: the
//! diagnosis written beside the alerts, the answered parameters applied to the live twin.

use super::alerts::{floats, window_values};
use super::background::{Background, Columns, Finished};
use super::checkpoint::State;
use super::options::WatchOptions;
use super::watcher::{open_stepper, Watcher};
use super::{background, WatchError};
use crate::fsutil::write_text_atomically;
use crate::twin::{ParameterValue, Twin, TwinError};
use crate::workflows::diagnose::Action;
use ::structure::channel::Channel;
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// A twin the watch adopted: live from `at` (s of the stream), written to `twin`, on the
/// verdict of the diagnosis `report`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Adopted {
    pub at: f64,
    pub twin: PathBuf,
    pub verdict: String,
    pub report: PathBuf,
}

/// The background diagnosis, when the watch runs one.
pub(super) fn background_of(
    twin: &Twin,
    options: &WatchOptions,
    state: &State,
    excitation: Channel,
    channels: &[Channel],
) -> Option<Background> {
    options.diagnosis.map(|o| {
        let diagnose = crate::workflows::diagnose::DiagnoseOptions {
            transient: options.transient,
            tolerance: options.tolerance,
            ..Default::default()
        };
        let columns = Columns {
            excitation,
            channels: channels.to_vec(),
        };
        let mut b = Background::new(twin, o, diagnose, state.background.clone(), columns);
        if let Some(dt) = state.dt {
            b.set_dt(dt);
        }
        b
    })
}

/// A diagnosis alert's answer: the diagnosis's action, reason, effects and scores, where its
/// fits started, and its report's and samples' paths.
pub(super) fn answer_fields(
    m: &mut serde_json::Map<String, Value>,
    d: &crate::workflows::diagnose::Diagnosis,
    path: &Path,
) {
    m.insert("action".into(), json!(d.action));
    m.insert("reason".into(), json!(d.reason));
    m.insert("effects".into(), json!(d.effects));
    m.insert("channels".into(), json!(d.channels));
    m.insert("nmse_before".into(), floats(&d.nmse_before));
    m.insert("nmse_after".into(), floats(&d.nmse_after));
    if let Some(at) = d.changed_at {
        // Its fits started there, from the state the twin reached on the samples before;
        // those after are the ones it scored.
        m.insert("fitted_from".into(), json!(at));
    }
    m.insert("report".into(), json!(path.display().to_string()));
    m.insert(
        "samples".into(),
        json!(path.with_extension("csv").display().to_string()),
    );
}

/// The physics parameters a firm verdict sets: a recalibration's every parameter; the
/// library effects `add_physics` names, switched on with their jointly fitted values, and the
/// physics that moved with them. None for any other verdict, and for a discovered effect (its
/// twin comes from `twin add-physics`, which refits its terms).
pub(super) fn answer(
    d: &crate::workflows::diagnose::Diagnosis,
) -> Option<Vec<(String, ParameterValue)>> {
    use crate::workflows::diagnose::Candidate;
    let real = |(name, value): (String, f64)| (name, ParameterValue::Real(value));
    match d.action {
        Action::Recalibrate => Some(
            d.recalibration
                .as_ref()?
                .parameters
                .iter()
                .map(|p| real((p.name.clone(), p.after)))
                .collect(),
        ),
        Action::AddPhysics if !d.effects.is_empty() => {
            let mut set = Vec::new();
            for e in &d.effects {
                let c = Candidate::parse(&e.name.label, structure::MAX_STOREYS).ok()?;
                set.extend(c.switches());
                for (name, short) in c.parameter_names() {
                    set.push(real((name, *e.parameters.get(short)?)));
                }
            }
            set.extend(
                d.physics_moved
                    .iter()
                    .map(|p| real((p.name.clone(), p.after))),
            );
            Some(set)
        }
        _ => None,
    }
}

/// The twin a firm verdict names ([`answer`]): `live` with those physics parameters, its noise
/// variances and posterior kept (the stream's noise did not change).
pub(super) fn answered(
    live: &Twin,
    parameters: &[(String, ParameterValue)],
) -> Result<Twin, WatchError> {
    let mut twin = live.duplicate();
    let physics = twin.component_mut(crate::twin::PHYSICS).ok_or_else(|| {
        WatchError::Twin(TwinError::Message(format!(
            "{} has no physics component",
            live.describe()
        )))
    })?;
    for (name, value) in parameters {
        physics.parameters.insert(name.clone(), value.clone());
    }
    twin.source = None;
    Ok(twin)
}

/// Where the `k`-th adopted twin goes: beside the alerts, `ALERTS.twin-k.ssp`.
pub(super) fn adopted_path(alerts: &Path, k: usize) -> PathBuf {
    let stem = alerts
        .file_stem()
        .map_or_else(|| "alerts".into(), |s| s.to_string_lossy().into_owned());
    alerts.with_file_name(format!("{stem}.twin-{k}.ssp"))
}

impl Watcher<'_> {
    /// A background diagnosis finished: its report beside the alerts, and a `diagnosis`
    /// alert (without a sequence number: when it comes depends on the machine).
    pub(super) fn diagnosed(&mut self, finished: Finished) -> Result<(), WatchError> {
        *self.state.alerts.entry("diagnosis".to_owned()).or_default() += 1;
        let job = &finished.job;
        if self
            .alerts
            .diagnosed
            .contains(&(job.window_start, job.round))
        {
            // Reported before a restart.
            return Ok(());
        }
        let mut body = self.diagnosis_body(&finished);
        let mut adoption = None;
        match &finished.result {
            Ok(d) => {
                let path = self.write_diagnosis(d, job)?;
                if self.options.adopt && finished.firm {
                    adoption = answer(d).map(|p| (p, background::verdict(d), path.clone()));
                }
                if let Value::Object(m) = &mut body {
                    answer_fields(m, d, &path);
                }
            }
            Err(error) => {
                if let Value::Object(m) = &mut body {
                    m.insert("error".into(), json!(error));
                }
            }
        }
        self.alerts.diagnosed.push((job.window_start, job.round));
        self.send(&body)?;
        let Some((parameters, verdict, report)) = adoption else {
            return Ok(());
        };
        self.adopt(&parameters, verdict, report)?;
        if let (Some(c), Some(b)) = (&finished.second, &mut self.background) {
            b.second(c);
        }
        Ok(())
    }

    /// The diagnosis alert's body before its answer: the samples it used (all from `from` to
    /// `to`; after a located change, those from the change on are the ones its error measures
    /// score) and, after a change, whether it is firm, its evidence, what it waited for.
    pub(super) fn diagnosis_body(&self, finished: &Finished) -> Value {
        let job = &finished.job;
        let (from, to) = job.span();
        let width = job.columns.width();
        let mut body = json!({
            "time": self.state.last_time, "kind": "diagnosis", "window_start": job.window_start,
            "from": from, "to": to, "samples_used": job.samples.len() / width,
            "seconds": finished.seconds, "round": job.round,
        });
        if let (Some(change), Value::Object(m)) = (job.change, &mut body) {
            m.insert("change_time".into(), json!(change));
            m.insert("post_change_seconds".into(), json!(to - change));
            m.insert("firm".into(), json!(finished.firm));
            if let Some(w) = &finished.weight {
                m.insert("evidence".into(), json!(w));
            }
            if let Some(b) = &finished.before {
                // Its effects against the samples before the change: there all along?
                m.insert("before_the_change".into(), json!(b));
            }
            if let Some(why) = &finished.because {
                // How much post-change data it waited for, and why that was enough.
                m.insert(
                    "waited".into(),
                    json!(format!(
                        "{:.1} s of post-change data, because {why}",
                        to - change
                    )),
                );
            }
            if let Some(c) = &finished.second {
                // It answered on the samples before a second change found in them.
                m.insert(
                    "second_change".into(),
                    json!({"time": c.time, "low": c.low, "high": c.high}),
                );
            }
        }
        body
    }

    /// The diagnosis report written beside the alerts, and the samples it ran on (for `twin
    /// add-physics --diagnosis R --data R.csv`, the live page's accept); the report's path.
    pub(super) fn write_diagnosis(
        &self,
        d: &crate::workflows::diagnose::Diagnosis,
        job: &background::Job,
    ) -> Result<PathBuf, WatchError> {
        let k = self.background.as_ref().map_or(0, |b| b.saved.reported);
        let path = background::report_path(&self.options.alerts, k);
        let text =
            serde_json::to_string_pretty(d).map_err(|e| WatchError::Checkpoint(e.to_string()))?;
        write_text_atomically(&path, &text)?;
        let samples = path.with_extension("csv");
        if let Ok(m) = background::record(job) {
            write_text_atomically(&samples, &crate::record::csv_text(&m))?;
        }
        Ok(path)
    }

    /// Adopt the twin a firm verdict names ([`answer`]): written beside the alerts, swapped in
    /// at the current point,
    /// the live twin of later diagnoses; an `adopted` alert, and the checkpoint records it. Its
    /// physics goes on from the state it reaches over the samples kept (from rest 70 s back
    /// with the defaults: what is left of the start is e^(−ζωt), far below the noise), not from
    /// the old twin's, which has been failing since the change; over the kept samples before
    /// that change the twins live then run instead ([`Background::reached`]: a structure that
    /// changed twice is not the second answer's before the first change). No sample is lost.
    pub(super) fn adopt(
        &mut self,
        parameters: &[(String, ParameterValue)],
        verdict: String,
        report: PathBuf,
    ) -> Result<(), WatchError> {
        let Some((time, excitation)) = self.stepper.last() else {
            return Ok(());
        };
        let adopted = answered(&self.live, parameters)?;
        let path = adopted_path(&self.options.alerts, self.state.adopted.len() + 1);
        adopted.write(&path)?;
        let (mut stepper, _) = open_stepper(
            &adopted,
            self.state.excitation,
            &self.state.channels,
            &self.options.learning,
        )?;
        let state = match self.background.as_ref().map(|b| (b, b.kept())) {
            Some((b, Ok(kept))) => b
                .reached(&adopted, &kept)
                .map_err(|e| WatchError::Twin(TwinError::Message(e.to_string())))?,
            _ => None,
        };
        match &state {
            Some(state) => stepper.start_from(time, state)?,
            None => stepper.start(time)?,
        }
        stepper.advance(time, excitation, &mut self.predicted)?;
        self.stepper = stepper;
        if let Some(b) = &mut self.background {
            b.adopted(&adopted);
        }
        // The comparison starts anew with the adopted twin (a segment of its own, the stream's
        // NMSE and window count going on): the windows open now are the change's, resolved
        // by it, and a further change opens a window (and an episode) of its own.
        let events = match &mut self.state.detector {
            Some(d) => d.finish_segment(),
            None => Vec::new(),
        };
        let open = self.cut_windows.len();
        self.events(time, events)?;
        let resolved = window_values(self.cut_windows.split_off(open));
        self.live = adopted;
        self.state.adopted.push(Adopted {
            at: time,
            twin: path.clone(),
            verdict: verdict.clone(),
            report: report.clone(),
        });
        self.alert(
            Some(time),
            "adopted",
            json!({"twin": path, "verdict": verdict, "report": report, "resolves": resolved,
                   "from": if state.is_some() { "its state over the samples kept" } else { "rest" },
                   "parameters": parameters.iter().map(|(n, v)| json!({"name": n, "value": match v {
                       ParameterValue::Real(x) => json!(x),
                       ParameterValue::Integer(i) => json!(i),
                       ParameterValue::Boolean(b) => json!(b),
                   }})).collect::<Vec<_>>()}),
        )
    }
}
