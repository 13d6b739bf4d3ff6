//! A policy checkpoint's provenance, typed: the `provenance` of its `policy.json` (how
//! the checkpoint was made: trained by `train policy`, or imported), and its
//! `provenance.json` (that, with the MuJoCo score `simulate --record` measured).
//!
//! Fields are declared in alphabetical order, the order the files had when they were
//! written as sorted JSON maps. A field this version does not know (a checkpoint written
//! by another version) is kept in `other` and written back, so `export-policies` never
//! drops it. The record of an import, different for every format, and the provenance of
//! a checkpoint a run started from are kept whole, as written.

use std::collections::BTreeMap;

use harness::provenance::Exported;
use harness::replay::attrs::Recipe;
use serde::{Deserialize, Serialize};
use serde_json::Value;

/// Mean pose errors on held-out frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseError {
    /// Agent position error (world units; the world is 512 wide, a pixel 5.3).
    pub agent: f64,
    /// Block position error (world units).
    pub block: f64,
    /// Block orientation error (degrees).
    pub angle_deg: f64,
    /// Goal position error (world units).
    pub goal: f64,
    /// Goal orientation error (degrees).
    pub goal_angle_deg: f64,
}

/// The held-out mean absolute error of one regressed state column.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColumnError {
    /// The column's name.
    pub name: String,
    /// Mean |prediction − truth|, in the state's units.
    pub mean_abs_error: f64,
}

/// The demonstrations a policy was trained on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DemosUsed {
    /// The behaviour its episodes were chosen by (`all`: every episode).
    pub behaviour: String,
    /// How the dataset was made (`None` for one evalharness did not make).
    pub collected_with: Option<Recipe>,
    /// Episodes used.
    pub episodes: usize,
    /// The dataset as given.
    pub path: String,
    /// Training samples (steps with a full observation window).
    pub samples: usize,
    /// Fields of another version.
    #[serde(flatten)]
    pub other: BTreeMap<String, Value>,
}

/// The checkpoint a fine-tuning run started from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolicyStart {
    /// Its epoch.
    pub epoch: u64,
    /// Its folder, as given.
    pub path: String,
    /// Its own provenance, whole.
    pub provenance: Value,
    /// Its optimiser step.
    pub step: u64,
}

/// The frame encoder's pose pre-training before the policy's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EncoderPretraining {
    /// Held-out error of each regressed state column (arm tasks).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heldout_mean_abs_error: Option<Vec<ColumnError>>,
    /// Held-out pose errors (Push-T).
    pub heldout_pose_error: Option<PoseError>,
    /// Steps done.
    pub steps: u64,
}

/// `raw`: a checkpoint of the trained weights themselves.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RawWeights {
    /// The trained weights.
    Raw,
}

/// Which weights a checkpoint holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Weights {
    /// The exponential moving average of the trained weights.
    Ema {
        /// Its decay.
        ema_decay: f64,
        /// Updates it has had.
        ema_updates: u64,
    },
    /// The trained weights (`"raw"`).
    Raw(RawWeights),
}

/// How a policy checkpoint was made: a `train policy` run, or an import (`import`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PolicyProvenance {
    /// The command line that made it (a resumed training run: its first session's).
    #[serde(default)]
    pub command: String,
    /// The commit of that binary.
    #[serde(default)]
    pub commit: String,
    /// The demonstrations it was trained on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data: Option<DemosUsed>,
    /// The run whose pre-trained frame encoder it started from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub encoder_from: Option<String>,
    /// The frame encoder's pre-training.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub encoder_pretraining: Option<EncoderPretraining>,
    /// Each export since, oldest first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub exported: Vec<Exported>,
    /// What an import read and how (each format says other things), whole.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub import: Option<Value>,
    /// The checkpoint a fine-tuning run started from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init_from: Option<PolicyStart>,
    /// The command line of the session that wrote this checkpoint, when it resumed the run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resumed_with: Option<String>,
    /// The training seed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Which weights the checkpoint holds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub weights: Option<Weights>,
    /// Fields of another version.
    #[serde(flatten)]
    pub other: BTreeMap<String, Value>,
}

impl PolicyProvenance {
    /// The provenance of a checkpoint made by `command` at `commit`, nothing else said yet.
    pub fn new(command: impl Into<String>, commit: impl Into<String>) -> Self {
        Self { command: command.into(), commit: commit.into(), ..Self::default() }
    }
}

/// A checkpoint's success in MuJoCo, measured by `simulate --policy DIR --record`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MujocoScore {
    /// Bootstrap 95% CI of the mean score.
    pub ci95: Option<[f64; 2]>,
    /// The commit of the binary that measured it.
    pub commit: String,
    /// The episodes' step limit.
    pub max_steps: usize,
    /// The mean score.
    pub mean: f64,
    /// The command line that measured it.
    pub measured_with: String,
    /// The first and last seed.
    pub seeds: [u64; 2],
    /// Wilson 95% CI of the success rate.
    pub success_ci95: [f64; 2],
    /// The success rate.
    pub success_rate: f64,
}

/// What any policy folder's `policy.json` says of how it was made, whatever its kind (a
/// scripted policy's has no epoch, step or loss).
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
pub struct Made {
    /// The checkpoint's epoch.
    #[serde(default)]
    pub epoch: Option<u64>,
    /// Its optimiser step.
    #[serde(default)]
    pub step: Option<u64>,
    /// Its training loss.
    #[serde(default)]
    pub train_loss: Option<f64>,
    /// How it was made.
    #[serde(default)]
    pub provenance: PolicyProvenance,
}

/// A checkpoint's `provenance.json`: its training provenance and its measured score.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolicyScores {
    /// The checkpoint's epoch (a scripted policy has none).
    pub epoch: Option<u64>,
    /// Its measured success in MuJoCo.
    pub mujoco_score: MujocoScore,
    /// Its optimiser step (a scripted policy has none).
    pub step: Option<u64>,
    /// Its training loss (an imported checkpoint has none).
    pub train_loss: Option<f64>,
    /// How it was made.
    pub training: PolicyProvenance,
    /// Fields of another version.
    #[serde(flatten)]
    pub other: BTreeMap<String, Value>,
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;

    /// Whether two JSON values hold the same keys and values, numbers compared as the `f32`
    /// they are read into where they differ as written: a `policy.json` written from its type
    /// (`train adapt`) prints the normalisation's `f32`s shortest (`0.6700263`), one written
    /// through `serde_json::Value` widened (`0.6700263023376465`), the same `f32`.
    fn same(a: &Value, b: &Value) -> bool {
        match (a, b) {
            (Value::Object(x), Value::Object(y)) => {
                x.len() == y.len() && x.iter().all(|(k, v)| y.get(k).is_some_and(|w| same(v, w)))
            }
            (Value::Array(x), Value::Array(y)) => {
                x.len() == y.len() && x.iter().zip(y).all(|(v, w)| same(v, w))
            }
            (Value::Number(x), Value::Number(y)) => {
                x == y || x.as_f64().zip(y.as_f64()).is_some_and(|(p, q)| p as f32 == q as f32)
            }
            _ => a == b,
        }
    }

    #[test]
    fn json_numbers_compare_as_the_f32_they_are_read_into() {
        let (short, wide) =
            (serde_json::json!({"m": [0.6700263]}), serde_json::json!({"m": [0.6700263023376465]}));
        assert!(same(&short, &wide));
        assert!(!same(&short, &serde_json::json!({"m": [0.67003]})));
        assert!(!same(&short, &serde_json::json!({"m": [0.6700263], "n": 1})));
    }

    /// Every policy checkpoint shipped under `checkpoints/` has a `policy.json` whose
    /// provenance, and a `provenance.json`, that read as their types and write back as the
    /// same JSON, so typing them dropped nothing.
    #[test]
    fn shipped_checkpoints_read_and_write_back_unchanged() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../checkpoints");
        let json = |p: &Path| -> Value {
            serde_json::from_str(&std::fs::read_to_string(p).expect("readable")).expect("JSON")
        };
        let mut seen = 0;
        for set in ["pusht/policies", "lift/policies", "can/policies"] {
            for entry in std::fs::read_dir(root.join(set)).expect("a shipped policy set") {
                let dir = entry.expect("entry").path();
                if !dir.is_dir() {
                    continue;
                }
                let file = crate::dir::read_policy_file(&dir).expect("policy.json");
                let known = file.provenance.other.is_empty()
                    && file.provenance.data.as_ref().is_some_and(|d| d.other.is_empty());
                assert!(known, "{}: fields the type does not name", dir.display());
                let written = serde_json::to_value(&file).expect("serialises");
                // Nulls the typed file leaves out read as absent, as before.
                let mut shipped = json(&dir.join("policy.json"));
                for key in ["encoder_from", "init_from"] {
                    if shipped["provenance"][key].is_null() {
                        shipped["provenance"].as_object_mut().expect("an object").remove(key);
                    }
                }
                assert!(same(&written, &shipped), "{}:\n{written}\n{shipped}", dir.display());
                let scores: PolicyScores = serde_json::from_value(json(&dir.join("provenance.json")))
                    .unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
                assert_eq!(scores.training, file.provenance, "{}", dir.display());
                seen += 1;
            }
        }
        // 7 Push-T checkpoints, 9 Lift, 9 Can.
        assert_eq!(seen, 25);
        // The scripted experts' scores: a policy without epoch, step or loss.
        for entry in std::fs::read_dir(root.join("pusht/scripted")).expect("the scripted set") {
            let dir = entry.expect("entry").path();
            if !dir.join("provenance.json").is_file() {
                continue;
            }
            let shipped = json(&dir.join("provenance.json"));
            let scores: PolicyScores = serde_json::from_value(shipped.clone()).expect("scores");
            assert_eq!(crate::dir::read_made(&dir).expect("policy.json").provenance, scores.training);
            assert_eq!(serde_json::to_value(&scores).expect("serialises"), shipped, "{}", dir.display());
            seen += 1;
        }
        assert_eq!(seen, 31);
    }
}
