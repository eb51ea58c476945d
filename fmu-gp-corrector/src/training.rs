//! The training file: the GP's training set and, optionally, its hyperparameters, as JSON.
//!
//! ```json
//! {
//!   "lags": 9,
//!   "target": "discrepancy",
//!   "inputs": [[0.01, 0.02, ...], ...],
//!   "targets": [[0.001, -0.002, 0.0005], ...],
//!   "hyperparameters": [
//!     {"length_scales": [1.0, ...], "signal_variance": 0.01, "noise_variance": 0.0001},
//!     {...},
//!     {...}
//!   ]
//! }
//! ```
//!
//! - `lags`: q, the number of lags; every input has `4 (q + 1)` values, laid out as
//!   [`crate::lags`] documents.
//! - `target`: what `targets` holds: `"discrepancy"` (measured − physics acceleration, the
//!   default form) or `"measured"` (the measured acceleration itself: the paper's zero-mean form).
//! - `inputs`, `targets`: one row per training point; `targets[n]` holds floors 1, 2, 3.
//! - `hyperparameters` (optional): one entry per floor, in floor order, each with one length
//!   scale per input. Absent, they are fitted (type-II maximum likelihood from data-based starts,
//!   [`crate::model::initial_fit_options`]) when the FMU is initialized; a file with no points
//!   and no hyperparameters leaves each GP at its prior with the `initial_*` parameters.
//!
//! Another layout than the paper's rig ([`crate::layout`]) writes its channels and excitation
//! too, and one target per channel ([`LayoutTraining`]):
//!
//! ```json
//! {
//!   "channels": ["acc1", "acc3", "acc5"],
//!   "excitation": "ground_acc",
//!   "lags": 9, "target": "discrepancy",
//!   "inputs": [[...], ...], "targets": [[0.001, -0.002, 0.0005], ...],
//!   "hyperparameters": [...]
//! }
//! ```
//!
//! - `channels` (absent: acc1, acc2, acc3): the measured channels in the corrector's order
//!   (accelerations, velocities, displacements, each by floor); `targets[n]` holds one value per
//!   channel, in the channel's own SI quantity (m/s², m/s, m);
//! - `excitation` (absent: `force`): `force` or `ground_acc`;
//! - `inputs`: the whole lag vector of each point, `(M + 1)(q + 1)` values for M channels
//!   ([`crate::lags`]); each channel's GP takes the blocks
//!   [`crate::layout::Layout::columns_of`] chooses, and its `hyperparameters` entry has one length
//!   scale per input of its own.
//!
//! Numbers are written in the shortest form that reads back as the same `f64` and read back
//! exactly, so a file round trip changes nothing. Unknown fields are an error (a misspelt
//! `hyperparameters` would otherwise be ignored silently).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::lags::input_dimension;
use crate::layout::Layout;
use crate::CorrectorError;

/// Largest number of lags the FMU accepts (the `lags` parameter's max).
pub const MAX_LAGS: usize = 64;

/// Largest training set one floor's GP holds; learning beyond it drops the oldest point.
pub const MAX_TRAINING_POINTS: usize = 2048;

/// What the GPs model.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TargetForm {
    /// The GP models measured − physics; corrected = physics + GP mean.
    #[default]
    Discrepancy,
    /// The GP models the measured acceleration itself (zero prior mean); corrected = GP mean.
    Measured,
}

impl TargetForm {
    /// The value of the `target` parameter.
    pub fn code(self) -> i32 {
        match self {
            TargetForm::Discrepancy => 0,
            TargetForm::Measured => 1,
        }
    }

    pub fn from_code(code: i32) -> Option<Self> {
        match code {
            0 => Some(TargetForm::Discrepancy),
            1 => Some(TargetForm::Measured),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            TargetForm::Discrepancy => "discrepancy",
            TargetForm::Measured => "measured",
        }
    }

    /// The GP target of one floor from a measured and a physics acceleration.
    pub fn target(self, measured: f64, physics: f64) -> f64 {
        match self {
            TargetForm::Discrepancy => measured - physics,
            TargetForm::Measured => measured,
        }
    }

    /// The corrected acceleration from a physics acceleration and the GP mean.
    pub fn corrected(self, physics: f64, gp_mean: f64) -> f64 {
        match self {
            TargetForm::Discrepancy => physics + gp_mean,
            TargetForm::Measured => gp_mean,
        }
    }
}

/// One floor's GP hyperparameters: Matérn 3/2 ARD kernel and Gaussian noise.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FloorHyperparameters {
    /// One per input, in the input vector's order (units of that input).
    pub length_scales: Vec<f64>,
    /// σ_f², (m/s²)².
    pub signal_variance: f64,
    /// σ_n², (m/s²)².
    pub noise_variance: f64,
}

impl FloorHyperparameters {
    /// Every length scale the same.
    pub fn isotropic(
        dimension: usize,
        length_scale: f64,
        signal_variance: f64,
        noise_variance: f64,
    ) -> Self {
        FloorHyperparameters {
            length_scales: vec![length_scale; dimension],
            signal_variance,
            noise_variance,
        }
    }

    /// Every value finite and positive, one length scale per input.
    pub fn check(&self, dimension: usize) -> Result<(), String> {
        if self.length_scales.len() != dimension {
            return Err(format!(
                "{} length scales, expected {dimension} (one per input)",
                self.length_scales.len()
            ));
        }
        if let Some((i, l)) = self
            .length_scales
            .iter()
            .enumerate()
            .find(|(_, l)| !(l.is_finite() && **l > 0.0))
        {
            return Err(format!(
                "length_scales[{i}] is {l}; it must be finite and > 0"
            ));
        }
        for (name, value) in [
            ("signal_variance", self.signal_variance),
            ("noise_variance", self.noise_variance),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!("{name} is {value}; it must be finite and > 0"));
            }
        }
        Ok(())
    }
}

/// The content of a training file (format in the module documentation).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainingFile {
    pub lags: usize,
    pub target: TargetForm,
    pub inputs: Vec<Vec<f64>>,
    /// Per point, the rig's floors 1..3 (this is the rig's own file format).
    pub targets: Vec<[f64; structure::paper::STOREYS]>,
    /// Written as `null` when absent (not skipped: the struct also travels in the FMU state,
    /// whose binary format has no optional fields); a file may leave it out.
    #[serde(default)]
    pub hyperparameters: Option<Vec<FloorHyperparameters>>,
}

impl TrainingFile {
    pub fn input_dimension(&self) -> usize {
        input_dimension(self.lags)
    }

    /// The whole file is consistent: lags in range, every row of the right length and finite,
    /// as many targets as inputs, three valid hyperparameter sets if any. Says what is wrong.
    pub fn check(&self) -> Result<(), String> {
        if self.lags > MAX_LAGS {
            return Err(format!("lags is {}, at most {MAX_LAGS}", self.lags));
        }
        let dimension = self.input_dimension();
        if self.inputs.len() != self.targets.len() {
            return Err(format!(
                "{} inputs but {} targets; there must be one target row per input",
                self.inputs.len(),
                self.targets.len()
            ));
        }
        if self.inputs.len() > MAX_TRAINING_POINTS {
            return Err(format!(
                "{} training points, more than the {MAX_TRAINING_POINTS} a floor's GP holds",
                self.inputs.len()
            ));
        }
        for (n, x) in self.inputs.iter().enumerate() {
            if x.len() != dimension {
                return Err(format!(
                    "inputs[{n}] has {} values, expected {dimension} = 4·(lags + 1) for lags = {}",
                    x.len(),
                    self.lags
                ));
            }
            if let Some(i) = x.iter().position(|v| !v.is_finite()) {
                return Err(format!("inputs[{n}][{i}] is not a finite number"));
            }
        }
        for (n, y) in self.targets.iter().enumerate() {
            if let Some(i) = y.iter().position(|v| !v.is_finite()) {
                return Err(format!("targets[{n}][{i}] is not a finite number"));
            }
        }
        if let Some(sets) = &self.hyperparameters {
            if sets.len() != 3 {
                return Err(format!(
                    "hyperparameters has {} entries, expected 3 (one per floor)",
                    sets.len()
                ));
            }
            for (floor, set) in sets.iter().enumerate() {
                set.check(dimension)
                    .map_err(|e| format!("hyperparameters[{floor}] (floor {}): {e}", floor + 1))?;
            }
        }
        Ok(())
    }

    /// Parse and check a training file's text; `source` names it in errors.
    pub fn from_json(text: &str, source: &str) -> Result<Self, CorrectorError> {
        let problem = |problem: String| CorrectorError::TrainingFile {
            path: source.to_owned(),
            problem,
        };
        let file: TrainingFile =
            serde_json::from_str(text).map_err(|e| problem(format!("not a training file: {e}")))?;
        file.check().map_err(problem)?;
        Ok(file)
    }

    /// Read and check a training file.
    pub fn read(path: &Path) -> Result<Self, CorrectorError> {
        let text = std::fs::read_to_string(path).map_err(|e| CorrectorError::TrainingFile {
            path: path.display().to_string(),
            problem: format!("cannot read it: {e}"),
        })?;
        Self::from_json(&text, &path.display().to_string())
    }

    pub fn to_json(&self) -> String {
        // A struct of numbers, strings and vectors always serializes.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    pub fn write(&self, path: &Path) -> Result<(), CorrectorError> {
        std::fs::write(path, self.to_json()).map_err(|e| CorrectorError::TrainingFile {
            path: path.display().to_string(),
            problem: format!("cannot write it: {e}"),
        })
    }
}

/// The training file of any layout (format in the module documentation); the paper rig's
/// [`TrainingFile`] is one without `channels` and `excitation`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayoutTraining {
    #[serde(default = "rig_channels")]
    pub channels: Vec<String>,
    #[serde(default = "rig_excitation")]
    pub excitation: String,
    pub lags: usize,
    pub target: TargetForm,
    pub inputs: Vec<Vec<f64>>,
    pub targets: Vec<Vec<f64>>,
    #[serde(default)]
    pub hyperparameters: Option<Vec<FloorHyperparameters>>,
}

fn rig_channels() -> Vec<String> {
    Layout::default().names()
}

fn rig_excitation() -> String {
    Layout::default().excitation_name()
}

impl From<TrainingFile> for LayoutTraining {
    fn from(f: TrainingFile) -> Self {
        LayoutTraining {
            channels: rig_channels(),
            excitation: rig_excitation(),
            lags: f.lags,
            target: f.target,
            inputs: f.inputs,
            targets: f.targets.into_iter().map(|y| y.to_vec()).collect(),
            hyperparameters: f.hyperparameters,
        }
    }
}

impl LayoutTraining {
    /// The layout its `channels` and `excitation` name (checked, in the corrector's order).
    pub fn layout(&self) -> Result<Layout, String> {
        let layout = Layout::from_names(&self.channels, &self.excitation)?;
        if layout.names() != self.channels {
            return Err(format!(
                "channels {:?} are not in the corrector's order {:?} (accelerations, velocities, \
                 displacements, each by floor)",
                self.channels,
                layout.names()
            ));
        }
        Ok(layout)
    }

    /// The paper rig's training file, when this is the rig's layout.
    pub fn to_rig(&self) -> Option<TrainingFile> {
        if !self.layout().is_ok_and(|l| l.is_paper()) {
            return None;
        }
        Some(TrainingFile {
            lags: self.lags,
            target: self.target,
            inputs: self.inputs.clone(),
            targets: self
                .targets
                .iter()
                .map(|y| <[f64; structure::paper::STOREYS]>::try_from(y.as_slice()).ok())
                .collect::<Option<_>>()?,
            hyperparameters: self.hyperparameters.clone(),
        })
    }

    /// The whole file is consistent (as [`TrainingFile::check`], per channel). Says what is
    /// wrong, naming the channel.
    pub fn check(&self) -> Result<Layout, String> {
        let layout = self.layout()?;
        if self.lags > MAX_LAGS {
            return Err(format!("lags is {}, at most {MAX_LAGS}", self.lags));
        }
        let dimension = layout.sample_width() * (self.lags + 1);
        let m = layout.channels.len();
        if self.inputs.len() != self.targets.len() {
            return Err(format!(
                "{} inputs but {} targets; there must be one target row per input",
                self.inputs.len(),
                self.targets.len()
            ));
        }
        if self.inputs.len() > MAX_TRAINING_POINTS {
            return Err(format!(
                "{} training points, more than the {MAX_TRAINING_POINTS} a channel's GP holds",
                self.inputs.len()
            ));
        }
        for (n, x) in self.inputs.iter().enumerate() {
            if x.len() != dimension {
                return Err(format!(
                    "inputs[{n}] has {} values, expected {dimension} = {}·(lags + 1) for {m} \
                     channel(s) and the excitation, lags = {}",
                    x.len(),
                    m + 1,
                    self.lags
                ));
            }
            if let Some(i) = x.iter().position(|v| !v.is_finite()) {
                return Err(format!("inputs[{n}][{i}] is not a finite number"));
            }
        }
        for (n, y) in self.targets.iter().enumerate() {
            if y.len() != m {
                return Err(format!(
                    "targets[{n}] has {} values, expected {m} (one per channel: {})",
                    y.len(),
                    self.channels.join(", ")
                ));
            }
            if let Some(i) = y.iter().position(|v| !v.is_finite()) {
                return Err(format!(
                    "targets[{n}][{i}] ({}) is not a finite number",
                    self.channels[i]
                ));
            }
        }
        if let Some(sets) = &self.hyperparameters {
            if sets.len() != m {
                return Err(format!(
                    "hyperparameters has {} entries, expected {m} (one per channel)",
                    sets.len()
                ));
            }
            for (j, set) in sets.iter().enumerate() {
                set.check(layout.input_dimension_of(j, self.lags))
                    .map_err(|e| format!("hyperparameters[{j}] ({}): {e}", self.channels[j]))?;
            }
        }
        Ok(layout)
    }

    /// Parse and check a training file's text of any layout; `source` names it in errors.
    pub fn from_json(text: &str, source: &str) -> Result<Self, CorrectorError> {
        let problem = |problem: String| CorrectorError::TrainingFile {
            path: source.to_owned(),
            problem,
        };
        let file: LayoutTraining =
            serde_json::from_str(text).map_err(|e| problem(format!("not a training file: {e}")))?;
        file.check().map_err(problem)?;
        Ok(file)
    }

    /// Read and check a training file of any layout.
    pub fn read(path: &Path) -> Result<Self, CorrectorError> {
        let text = std::fs::read_to_string(path).map_err(|e| CorrectorError::TrainingFile {
            path: path.display().to_string(),
            problem: format!("cannot read it: {e}"),
        })?;
        Self::from_json(&text, &path.display().to_string())
    }

    /// The JSON text: the paper rig's [`TrainingFile`] format on the rig's layout.
    pub fn to_json(&self) -> String {
        match self.to_rig() {
            Some(rig) => rig.to_json(),
            // A struct of numbers, strings and vectors always serializes.
            None => serde_json::to_string_pretty(self).unwrap_or_default(),
        }
    }

    pub fn write(&self, path: &Path) -> Result<(), CorrectorError> {
        std::fs::write(path, self.to_json()).map_err(|e| CorrectorError::TrainingFile {
            path: path.display().to_string(),
            problem: format!("cannot write it: {e}"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> TrainingFile {
        TrainingFile {
            lags: 1,
            target: TargetForm::Discrepancy,
            inputs: vec![vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8]; 2],
            targets: vec![[0.01, 0.02, 0.03], [0.1 + 0.2, 1e-17, -3.0]],
            hyperparameters: Some(vec![FloorHyperparameters::isotropic(8, 1.0, 0.01, 1e-4); 3]),
        }
    }

    #[test]
    fn a_file_round_trips_exactly() {
        let file = small();
        let back = TrainingFile::from_json(&file.to_json(), "mem").expect("valid");
        assert_eq!(back, file);
    }

    #[test]
    fn hyperparameters_are_optional() {
        let mut file = small();
        file.hyperparameters = None;
        assert_eq!(
            TrainingFile::from_json(&file.to_json(), "mem").expect("valid"),
            file
        );
        let without = r#"{"lags": 0, "target": "measured", "inputs": [[1, 2, 3, 4]], "targets": [[1, 2, 3]]}"#;
        let read = TrainingFile::from_json(without, "mem").expect("valid");
        assert_eq!(read.hyperparameters, None);
    }

    #[track_caller]
    fn problem(file: &TrainingFile) -> String {
        TrainingFile::from_json(&file.to_json(), "t.json")
            .expect_err("refused")
            .to_string()
    }

    #[test]
    fn inconsistent_files_are_refused_with_the_reason() {
        let mut f = small();
        f.inputs[1].pop();
        assert!(problem(&f).contains("inputs[1] has 7 values, expected 8"));

        let mut f = small();
        f.targets.pop();
        assert!(problem(&f).contains("2 inputs but 1 targets"));

        let mut f = small();
        f.lags = MAX_LAGS + 1;
        assert!(problem(&f).contains("at most"));

        let mut f = small();
        if let Some(h) = f.hyperparameters.as_mut() {
            h.pop();
        }
        assert!(problem(&f).contains("2 entries, expected 3"));

        let mut f = small();
        if let Some(h) = f.hyperparameters.as_mut() {
            h[2].noise_variance = 0.0;
        }
        let text = problem(&f);
        assert!(
            text.contains("floor 3") && text.contains("noise_variance"),
            "{text}"
        );

        let mut f = small();
        if let Some(h) = f.hyperparameters.as_mut() {
            h[0].length_scales.push(1.0);
        }
        assert!(problem(&f).contains("9 length scales, expected 8"));
    }

    #[test]
    fn syntax_errors_unknown_fields_and_bad_targets_name_the_file() {
        for (text, needle) in [
            ("{", "EOF"),
            (
                r#"{"lags": 1, "target": "physics", "inputs": [], "targets": []}"#,
                "physics",
            ),
            (
                r#"{"lags": 1, "target": "discrepancy", "inputs": [], "targets": [], "hyperparameter": []}"#,
                "hyperparameter",
            ),
            (
                r#"{"lags": -1, "target": "discrepancy", "inputs": [], "targets": []}"#,
                "-1",
            ),
            (
                r#"{"lags": 0, "target": "measured", "inputs": [[1,2,3,4]], "targets": [[1,2]]}"#,
                "3",
            ),
        ] {
            let e = TrainingFile::from_json(text, "bad.json").expect_err(text);
            let message = e.to_string();
            assert!(message.starts_with("training file bad.json: "), "{message}");
            assert!(message.contains(needle), "{message}");
        }
    }

    #[test]
    fn non_finite_values_are_refused() {
        // JSON has no NaN; a huge literal overflows to infinity on reading.
        let text = r#"{"lags": 0, "target": "measured", "inputs": [[1e999, 0, 0, 0]], "targets": [[0, 0, 0]]}"#;
        let message = TrainingFile::from_json(text, "inf.json")
            .expect_err("infinite")
            .to_string();
        assert!(message.contains("inf.json"), "{message}");
    }

    #[test]
    fn a_layout_file_round_trips_and_an_old_file_reads_as_the_rig() {
        let old = small();
        let read = LayoutTraining::from_json(&old.to_json(), "old.json").expect("valid");
        assert_eq!(read, LayoutTraining::from(old.clone()));
        assert_eq!(read.to_rig(), Some(old));
        let five = LayoutTraining {
            channels: vec!["acc1".into(), "acc3".into()],
            excitation: "ground_acc".into(),
            lags: 0,
            target: TargetForm::Discrepancy,
            inputs: vec![vec![0.1, 0.2, 0.3]; 2],
            targets: vec![vec![0.01, -0.02]; 2],
            hyperparameters: Some(vec![FloorHyperparameters::isotropic(3, 1.0, 0.01, 1e-4); 2]),
        };
        let back = LayoutTraining::from_json(&five.to_json(), "five.json").expect("valid");
        assert_eq!(back, five);
        assert_eq!(back.to_rig(), None);
        let mut bad = five.clone();
        bad.targets[1].push(0.0);
        let e = LayoutTraining::from_json(&bad.to_json(), "five.json")
            .expect_err("three targets")
            .to_string();
        assert!(e.contains("targets[1] has 3 values, expected 2"), "{e}");
        let mut bad = five;
        bad.channels.reverse();
        let e = LayoutTraining::from_json(&bad.to_json(), "five.json")
            .expect_err("order")
            .to_string();
        assert!(e.contains("not in the corrector's order"), "{e}");
    }
}
