//! A dataset's `evalharness` attributes, typed: what every command that makes a dataset
//! (`collect`, `collect --policy`, `simulate --replay-imagined --record`, `dataset merge`)
//! writes under the root's `.zattrs`, and what the trainers' provenance, `dataset info`,
//! `dataset merge` and the readers of per-episode labels read back.
//!
//! The attributes cross processes (a dataset is written by one command and read by
//! another, often on another day), so they are one struct on both sides. Reading is
//! lenient where it must be: every field but the version is optional (a merged dataset
//! records no seeds, a Push-T one no `success` description), unknown fields are ignored
//! (a dataset written by a later version still reads), and a dataset without evalharness
//! attributes at all (another codebase's replay buffer) reads as `None`. A field of the
//! wrong type is refused naming the dataset, never read as absent.
//!
//! They are written through `serde_json::Value`, whose maps keep keys in alphabetical
//! order: the bytes of `.zattrs` are those the untyped writers made before.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::ReplayError;

/// A dataset's `evalharness` attributes.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DatasetAttrs {
    /// The evalharness version that wrote the dataset.
    #[serde(default)]
    pub version: Option<String>,
    /// The task (`pusht`, `lift`, `can`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenario: Option<String>,
    /// The task's configuration, as the task serialises it (read back by the task).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenario_config: Option<Value>,
    /// What each `data/state` column holds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub state_columns: Option<Vec<String>>,
    /// What `data/action` holds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action: Option<String>,
    /// What `data/coverage` holds (Push-T).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coverage: Option<String>,
    /// What `data/success` holds (Lift, Can).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub success: Option<String>,
    /// Which camera `data/img` shows (Lift, Can).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image: Option<String>,
    /// The first episode's seed (episode i has seed `seed_start + i`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed_start: Option<u64>,
    /// The step limit of every episode.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_steps: Option<u64>,
    /// How the episodes were made.
    #[serde(flatten)]
    pub source: Source,
    /// `dataset merge`: each input, its attributes without their episode list.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub merged_from: Option<Vec<MergedPart>>,
    /// One entry per episode, in order (none in a merge input's copy).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub episodes: Vec<EpisodeEntry>,
}

/// How a dataset's episodes were made: `collect`'s mix and perturbation, `collect
/// --policy`'s checkpoints, or `simulate --replay-imagined --record`'s world model (stored
/// beside the other attributes, not under a key of its own).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Source {
    /// `collect --mix`: the behaviour mix, as given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mix: Option<String>,
    /// `collect --noise`: the expert's action noise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise: Option<f64>,
    /// `collect --lag`: the expert's control lag, steps.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lag: Option<u64>,
    /// `--no-early-stop` (Lift, Can): episodes kept going after success.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub no_early_stop: Option<bool>,
    /// `collect --policy`: the checkpoint or folder of them that acted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub policy: Option<String>,
    /// `collect --policy`: each checkpoint run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub checkpoints: Option<Vec<CheckpointEntry>>,
    /// `simulate --replay-imagined --record`: the world model whose episodes' actions were
    /// replayed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub replay_imagined: Option<PathBuf>,
    /// `simulate --replay-imagined --record`: the judge of the imagined episodes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub judge: Option<PathBuf>,
    /// `simulate --replay-imagined --record`: the world model's sampling-noise scale.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_scale: Option<f32>,
    /// `simulate --replay-imagined --record`: the run's master seed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// What the episodes are, where the command says so in words.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub what: Option<String>,
}

/// One episode's entry.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EpisodeEntry {
    /// The behaviour that acted (`expert`, `miss`, …; a checkpoint's name for `collect
    /// --policy`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub behaviour: Option<String>,
    /// The episode's seed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Control steps recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub steps: Option<u64>,
    /// The task's score (Push-T).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub score: Option<f64>,
    /// Whether the task succeeded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub success: Option<bool>,
    /// `simulate --replay-imagined --record`: whether the world model imagined the
    /// episode succeeding.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub imagined_success: Option<bool>,
    /// `dataset merge`: the index of the input it came from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<u64>,
}

/// One checkpoint of `collect --policy`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckpointEntry {
    /// The policy's name.
    pub name: String,
    /// Its folder.
    pub path: PathBuf,
    /// Episodes it ran.
    pub episodes: u64,
    /// Its mean score over them.
    pub mean_score: f64,
}

/// One input of `dataset merge`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MergedPart {
    /// The input dataset, as given.
    pub path: String,
    /// Its episodes.
    pub episodes: u64,
    /// Its attributes, without the episode list (none for a dataset without evalharness
    /// attributes).
    pub attrs: Option<DatasetAttrs>,
}

/// The root attributes around them.
#[derive(Serialize, Deserialize)]
struct Root {
    evalharness: Option<DatasetAttrs>,
}

impl DatasetAttrs {
    /// Attributes written by this build: its version, the rest empty.
    pub fn new() -> Self {
        Self { version: Some(env!("CARGO_PKG_VERSION").to_string()), ..Self::default() }
    }

    /// The attributes in a dataset group's root attributes `attrs` (the group at `path`);
    /// `None` for a dataset without evalharness attributes.
    ///
    /// # Errors
    /// [`ReplayError::Layout`] naming `path` for attributes of the wrong shape.
    pub fn from_root(path: &Path, attrs: &Value) -> Result<Option<Self>, ReplayError> {
        serde_path_to_error::deserialize::<_, Root>(attrs).map(|r| r.evalharness).map_err(|e| {
            ReplayError::Layout {
                path: path.to_path_buf(),
                reason: format!("its evalharness attributes cannot be read: {}: {}", e.path(), e.inner()),
            }
        })
    }

    /// The root attributes that hold these (`{"evalharness": …}`), keys in alphabetical order.
    pub fn to_root(&self) -> Value {
        serde_json::to_value(Root { evalharness: Some(self.clone()) })
            .expect("dataset attributes are plain data")
    }

    /// Steps over the episodes that record them.
    pub fn total_steps(&self) -> u64 {
        total_steps(&self.episodes)
    }
}

/// Steps over the `episodes` that record them.
pub fn total_steps(episodes: &[EpisodeEntry]) -> u64 {
    episodes.iter().filter_map(|e| e.steps).sum()
}

/// How to make a dataset again (`collect` is deterministic: the same arguments give the
/// same bytes), for a trainer's provenance; a merged dataset lists each input's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Recipe {
    /// The command that makes it (`DATASET` standing for a merge's output).
    pub command: String,
    /// A merge's inputs' recipes, in order (none for an input that was not made by evalharness).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inputs: Option<Vec<Option<Recipe>>>,
    /// `collect --policy`'s checkpoints.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub checkpoints: Option<Vec<CheckpointEntry>>,
    /// The version that wrote the dataset.
    #[serde(default)]
    pub evalharness_version: Option<String>,
    /// The scenario's parameters the dataset was made with, as it records them
    /// (`scenario_config`; for Lift and Can it includes how frames were rendered). Where they
    /// are not the task's shipped ones, the command's `--scenario NAME` stands for a scenario
    /// file holding them. Absent for a merge (each input's recipe has its own) and for a
    /// dataset that does not record them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenario_config: Option<Value>,
}

/// A value as JSON writes it (`null` when absent): the numbers of a recipe's command
/// read as the attributes hold them (`0.0`, not `0`).
fn js<T: Serialize>(v: &Option<T>) -> String {
    serde_json::to_string(v).unwrap_or_else(|_| "null".into())
}

impl DatasetAttrs {
    /// The recipe of the dataset these attributes describe; `episodes` overrides the
    /// count (a merge input's copy no longer lists its episodes).
    pub fn recipe(&self, episodes: Option<u64>) -> Recipe {
        let version = self.version.clone();
        if let Some(parts) = &self.merged_from {
            let paths: Vec<&str> = parts.iter().map(|p| p.path.as_str()).collect();
            return Recipe {
                command: format!("evalharness dataset merge {} --out DATASET", paths.join(" ")),
                inputs: Some(
                    parts.iter().map(|p| p.attrs.as_ref().map(|a| a.recipe(Some(p.episodes)))).collect(),
                ),
                checkpoints: None,
                evalharness_version: version,
                scenario_config: None,
            };
        }
        let episodes = episodes.unwrap_or(self.episodes.len() as u64);
        // Push-T is the default scenario; Lift and Can datasets name theirs.
        let scenario = match self.scenario.as_deref() {
            Some(name) if name != "pusht" => format!(" --scenario {name}"),
            _ => String::new(),
        };
        let run_on = if self.source.no_early_stop == Some(true) { " --no-early-stop" } else { "" };
        let (seed_start, max_steps) = (js(&self.seed_start), js(&self.max_steps));
        if let (Some(policy), Some(wm)) = (&self.source.policy, &self.source.replay_imagined) {
            return Recipe {
                command: self.replay_command(&scenario, policy, wm, episodes, (&seed_start, &max_steps)),
                inputs: None,
                checkpoints: None,
                evalharness_version: version,
                scenario_config: self.scenario_config.clone(),
            };
        }
        if let Some(policy) = &self.source.policy {
            // `collect --policy`: `--episodes` counts per checkpoint.
            let per = episodes / self.source.checkpoints.as_ref().map_or(1, |c| c.len().max(1) as u64);
            return Recipe {
                command: format!(
                    "evalharness collect{scenario} --policy {policy} --episodes {per} --seed-start {seed_start} --max-steps {max_steps}{run_on}"
                ),
                inputs: None,
                checkpoints: self.source.checkpoints.clone(),
                evalharness_version: version,
                scenario_config: self.scenario_config.clone(),
            };
        }
        Recipe {
            command: format!(
                "evalharness collect{scenario} --episodes {episodes} --seed-start {seed_start} --mix {} --noise {} --lag {} --max-steps {max_steps}{run_on}",
                self.source.mix.as_deref().unwrap_or("?"),
                js(&self.source.noise),
                js(&self.source.lag)
            ),
            inputs: None,
            checkpoints: None,
            evalharness_version: version,
            scenario_config: self.scenario_config.clone(),
        }
    }

    /// `simulate --replay-imagined --record`'s command for these attributes (`scenario`,
    /// `seed_start` and `max_steps` as [`Self::recipe`] writes them): `--episodes` counts per
    /// checkpoint, and each checkpoint's episodes carry its own behaviour label.
    fn replay_command(
        &self,
        scenario: &str,
        policy: &str,
        wm: &Path,
        episodes: u64,
        (seed_start, max_steps): (&str, &str),
    ) -> String {
        let labels: std::collections::BTreeSet<&str> =
            self.episodes.iter().filter_map(|e| e.behaviour.as_deref()).collect();
        let per = episodes / (labels.len().max(1) as u64);
        let judge =
            self.source.judge.as_ref().map(|j| format!(" --judge {}", j.display())).unwrap_or_default();
        let noise = self.source.noise_scale.map(|t| format!(" --noise-scale {t}")).unwrap_or_default();
        format!(
            "evalharness simulate{scenario} --policy {policy} --replay-imagined {}{judge}{noise} --seed {} --episodes {per} --seed-start {seed_start} --max-steps {max_steps} --record DATASET --out OUT",
            wm.display(),
            self.source.seed.unwrap_or(0),
        )
    }
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;

    fn attrs(v: Value) -> DatasetAttrs {
        DatasetAttrs::from_root(Path::new("d.zarr"), &json!({ "evalharness": v })).unwrap().unwrap()
    }

    #[test]
    fn recipes_regenerate_scripted_policy_and_merged_datasets() {
        let mix = attrs(json!({"seed_start": 0, "mix": "expert=1", "noise": 0.0, "lag": 0, "max_steps": 300,
                               "episodes": [{}, {}, {}], "version": "0.1.0"}));
        assert_eq!(
            mix.recipe(None).command,
            "evalharness collect --episodes 3 --seed-start 0 --mix expert=1 --noise 0.0 --lag 0 --max-steps 300"
        );
        // `collect --policy`: 4 episodes of 2 checkpoints are `--episodes 2`.
        let entry = |name: &str| json!({"name": name, "path": "runs/p", "episodes": 2, "mean_score": 0.5});
        let pol = attrs(json!({"seed_start": 7, "policy": "runs/p", "checkpoints": [entry("a"), entry("b")],
                               "max_steps": 24, "episodes": [{}, {}, {}, {}], "version": "0.1.0"}));
        let r = pol.recipe(None);
        assert_eq!(
            r.command,
            "evalharness collect --policy runs/p --episodes 2 --seed-start 7 --max-steps 24"
        );
        assert_eq!(r.checkpoints.unwrap()[1].name, "b");
        // Regression: a Lift dataset's command lacked `--scenario lift` and `--no-early-stop`,
        // so it regenerated Push-T data.
        let lift = attrs(
            json!({"scenario": "lift", "seed_start": 5, "mix": "expert=1", "noise": 0.0, "lag": 0,
                                "max_steps": 150, "no_early_stop": true, "episodes": [{}], "version": "0.1.0"}),
        );
        assert_eq!(
            lift.recipe(None).command,
            "evalharness collect --scenario lift --episodes 1 --seed-start 5 --mix expert=1 --noise 0.0 --lag 0 --max-steps 150 --no-early-stop"
        );
        assert_eq!(lift.recipe(None).scenario_config, None);
        // A dataset that records its scenario's parameters (how its frames were rendered)
        // passes them on, so that `--scenario lift` is not mistaken for the shipped rendering.
        let visual = json!({"visual": {"samples": 4, "reflections": true}});
        let mut with = lift.clone();
        with.scenario_config = Some(visual.clone());
        assert_eq!(with.recipe(None).scenario_config, Some(visual));
        let lift_pol =
            attrs(json!({"scenario": "lift", "seed_start": 7, "policy": "p", "checkpoints": [entry("p")],
                                    "max_steps": 9, "episodes": [{}], "version": "0.1.0"}));
        assert_eq!(
            lift_pol.recipe(None).command,
            "evalharness collect --scenario lift --policy p --episodes 1 --seed-start 7 --max-steps 9"
        );
        // A merge: each input's recipe with its own episode count.
        let merged = attrs(json!({"version": "0.1.0", "merged_from": [
            {"path": "a.zarr", "episodes": 2, "attrs": {"seed_start": 0, "mix": "expert=1", "noise": 0.0,
                                                         "lag": 0, "max_steps": 300, "version": "0.1.0"}},
            {"path": "b.zarr", "episodes": 1, "attrs": {"seed_start": 9, "mix": "explore=1", "noise": 80.0,
                                                         "lag": 2, "max_steps": 300, "version": "0.1.0"}}],
            "episodes": [{}, {}, {}]}));
        let r = merged.recipe(None);
        assert_eq!(r.command, "evalharness dataset merge a.zarr b.zarr --out DATASET");
        let inputs: Vec<Recipe> = r.inputs.unwrap().into_iter().flatten().collect();
        assert_eq!(
            inputs[1].command,
            "evalharness collect --episodes 1 --seed-start 9 --mix explore=1 --noise 80.0 --lag 2 --max-steps 300"
        );
        assert!(inputs[0].command.contains("--episodes 2 "), "{}", inputs[0].command);
    }

    /// Regression: a `simulate --replay-imagined --record` dataset's recipe read as `collect
    /// --policy`, which makes other episodes.
    #[test]
    fn a_replayed_dataset_is_remade_by_simulate() {
        // 2 checkpoints' labels over 4 episodes: 2 episodes each.
        let ep = |b: &str| json!({"behaviour": b, "seed": 1});
        let a = attrs(json!({"scenario": "lift", "seed_start": 7, "max_steps": 150, "policy": "pol",
            "replay_imagined": "wm", "judge": "j", "noise_scale": 0.5, "seed": 3, "version": "0.1.0",
            "episodes": [ep("a/imagined-actions"), ep("a/imagined-actions"), ep("b/imagined-actions"),
                         ep("b/imagined-actions")]}));
        assert_eq!(
            a.recipe(None).command,
            "evalharness simulate --scenario lift --policy pol --replay-imagined wm --judge j --noise-scale 0.5 \
             --seed 3 --episodes 2 --seed-start 7 --max-steps 150 --record DATASET --out OUT"
        );
    }

    #[test]
    fn attributes_of_the_wrong_shape_are_refused_and_foreign_datasets_have_none() {
        let p = Path::new("d.zarr");
        assert_eq!(DatasetAttrs::from_root(p, &json!({})).unwrap(), None);
        let e =
            DatasetAttrs::from_root(p, &json!({"evalharness": {"episodes": [{"seed": "x"}]}})).unwrap_err();
        assert!(e.to_string().contains("d.zarr"), "{e}");
        // Fields of a later version are ignored; written attributes keep their keys sorted.
        let a = attrs(json!({"version": "9.0", "scenario": "lift", "a_later_field": 1}));
        assert_eq!(a.scenario.as_deref(), Some("lift"));
        let text =
            serde_json::to_string(&DatasetAttrs { seed_start: Some(3), ..DatasetAttrs::new() }.to_root())
                .unwrap();
        assert_eq!(
            text,
            format!(r#"{{"evalharness":{{"seed_start":3,"version":"{}"}}}}"#, env!("CARGO_PKG_VERSION"))
        );
    }
}
