//! The `config.json` of a `rank` and of a `plan` run folder, typed.
//!
//! A run writes its resolved settings before its first batch; `--resume` reads them
//! back and compares them setting by setting ([`crate::resume`]), `merge` checks that
//! its shards agree on them and writes the joined run's ([`crate::shards`]), and
//! `report` names the models they list. The field names are those the files have had
//! since `rank` first wrote them, so a folder written before these types existed reads
//! as it is; a file with a setting this version does not know is refused, naming it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use judges::folder::Label;
use judges::metrics::JudgeMetrics;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use world_model::model::WorldModelConfig;

use crate::error::RunError;

/// `rank`'s resolved settings (`OUT/config.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RankConfig {
    /// The command line that started (or last resumed) the run.
    pub command: String,
    /// `--scenario`: a task's name or a scenario file.
    pub scenario: String,
    /// The task's parameters as the run loaded them (for Lift and Can, how frames were
    /// rendered; [`harness::task::Task::parameters`]); absent in folders written before it
    /// was recorded. A record: `--resume` and `merge` compare them by their fingerprint
    /// (`fingerprints["scenario parameters"]`), as they do every input.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenario_parameters: Option<serde_json::Value>,
    /// `--policies`: the folder of checkpoints (or one checkpoint).
    pub policies: PathBuf,
    /// `--world-model`: its folder.
    pub world_model: PathBuf,
    /// The world model's configuration as the run used it (`--alpha`,
    /// `--noise-scale` applied).
    pub world_model_config: WorldModelConfig,
    /// Episodes per policy.
    pub episodes: usize,
    /// The first episode seed.
    pub seed_start: u64,
    /// Control steps per episode at most.
    pub max_steps: usize,
    /// Episodes per batch (the batch size changes float rounding, so it is kept).
    pub batch: usize,
    /// The master seed of the per-episode noise streams.
    pub seed: u64,
    /// Bootstrap resamples of the confidence intervals.
    pub bootstrap: usize,
    /// This folder's shard `(i, n)` of the run's batches; `(0, 1)` for a whole run.
    pub shard: (usize, usize),
    /// The policy checkpoints ranked, in run order.
    pub checkpoints: Vec<PathBuf>,
    /// Each input's content fingerprint, by name (`world_model`, `policy NAME`,
    /// `judge`, `scenario`, ...).
    pub fingerprints: BTreeMap<String, String>,
    /// The learned judge of imagined frames (`--judge`), when one was given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub judge: Option<JudgeSettings>,
    /// `--judge-every-frame` (written only when set).
    #[serde(default, skip_serializing_if = "is_false")]
    pub judge_every_frame: bool,
    /// `--float-frames` (written only when set).
    #[serde(default, skip_serializing_if = "is_false")]
    pub float_frames: bool,
    /// The shard folders `merge` joined this run from (empty for a run done whole).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub merged_from: Vec<PathBuf>,
}

/// The judge a `rank` run scored imagined frames with, as it read them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JudgeSettings {
    /// The judge's folder.
    pub path: PathBuf,
    /// What it estimates.
    pub label: Label,
    /// The value above which an episode succeeds.
    pub threshold: f64,
    /// Judged frames in a row that must show success (`--judge-persist` applied).
    pub persist_frames: usize,
    /// Its reading of its held-out episodes.
    pub heldout: JudgeMetrics,
}

/// `plan`'s resolved settings (`OUT/config.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanConfig {
    /// The command line that started (or last resumed) the run.
    pub command: String,
    /// `--scenario`.
    pub scenario: String,
    /// `--policy`: the proposing checkpoint.
    pub policy: PathBuf,
    /// `--world-model`, when a planner imagines in it.
    pub world_model: Option<PathBuf>,
    /// Its configuration as used, when it is.
    pub world_model_config: Option<WorldModelConfig>,
    /// The planners compared (`none`, `world-model`, `simulator`).
    pub planners: Vec<String>,
    /// Proposals per decision.
    pub proposals: usize,
    /// Actions of each proposal imagined.
    pub imagine: usize,
    /// Actions of the chosen proposal executed.
    pub execute: usize,
    /// The spread of the proposals' noise.
    pub spread: f32,
    /// The margin by which a proposal must beat the policy's own.
    pub margin: f64,
    /// `--judge`, when the cost is a judge's.
    pub judge: Option<PathBuf>,
    /// What the planners minimise, in words.
    pub cost: String,
    /// Episodes.
    pub episodes: usize,
    /// The first episode seed.
    pub seed_start: u64,
    /// Control steps per episode at most.
    pub max_steps: usize,
    /// Episodes per batch.
    pub batch: usize,
    /// The master seed.
    pub seed: u64,
    /// Bootstrap resamples.
    pub bootstrap: usize,
    /// Episodes whose decisions are recorded.
    pub record: usize,
    /// Each input's content fingerprint, by name.
    pub fingerprints: BTreeMap<String, String>,
}

#[allow(clippy::trivially_copy_pass_by_ref)] // serde's `skip_serializing_if` passes a reference
fn is_false(b: &bool) -> bool {
    !*b
}

/// What the resume and merge rules need of a run's configuration.
pub trait RunSettings: Serialize + DeserializeOwned {
    /// `rank` or `plan`, for messages.
    const KIND: &'static str;
    /// Every setting but the command line, as (name in the file, value as JSON text),
    /// for comparing two runs setting by setting and naming what differs.
    fn settings(&self) -> Vec<(&'static str, String)>;
    /// The inputs' content fingerprints.
    fn fingerprints(&self) -> &BTreeMap<String, String>;
    /// The run's seeds and how they are cut and shared out.
    fn span(&self) -> Span;
}

/// A run's seeds and how they are cut and shared out: what decides whether it can grow.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Span {
    /// Episodes per policy.
    pub episodes: usize,
    /// Episodes per batch.
    pub batch: usize,
    /// The first episode seed.
    pub seed_start: u64,
    /// The folder's shard `(i, n)` of the run.
    pub shard: (usize, usize),
}

/// Every setting of `a` and `b` but those in `skip` whose values differ, as (name,
/// `a`'s value, `b`'s value), the values as JSON text.
pub(crate) fn differing<C: RunSettings>(a: &C, b: &C, skip: &[&str]) -> Vec<(&'static str, String, String)> {
    a.settings()
        .into_iter()
        .zip(b.settings())
        .filter(|((name, x), (_, y))| !skip.contains(name) && x != y)
        .map(|((name, x), (_, y))| (name, x, y))
        .collect()
}

/// A setting's value as JSON text, for comparing and showing.
fn text<T: Serialize + ?Sized>(v: &T) -> String {
    serde_json::to_string(v).unwrap_or_else(|e| format!("<unprintable: {e}>"))
}

/// `(name, text)` pairs of the named fields of `self`.
macro_rules! named {
    ($s:ident: $($f:ident),+ $(,)?) => { vec![$((stringify!($f), text(&$s.$f))),+] };
}

impl RunSettings for RankConfig {
    const KIND: &'static str = "rank";
    fn settings(&self) -> Vec<(&'static str, String)> {
        named!(self: scenario, policies, world_model, world_model_config, episodes, seed_start,
            max_steps, batch, seed, bootstrap, shard, checkpoints, fingerprints, judge,
            judge_every_frame, float_frames, merged_from)
    }
    fn fingerprints(&self) -> &BTreeMap<String, String> {
        &self.fingerprints
    }
    fn span(&self) -> Span {
        Span { episodes: self.episodes, batch: self.batch, seed_start: self.seed_start, shard: self.shard }
    }
}

impl RunSettings for PlanConfig {
    const KIND: &'static str = "plan";
    fn settings(&self) -> Vec<(&'static str, String)> {
        named!(self: scenario, policy, world_model, world_model_config, planners, proposals,
            imagine, execute, spread, margin, judge, cost, episodes, seed_start, max_steps, batch,
            seed, bootstrap, record, fingerprints)
    }
    fn fingerprints(&self) -> &BTreeMap<String, String> {
        &self.fingerprints
    }
    fn span(&self) -> Span {
        // A plan is never sharded.
        Span { episodes: self.episodes, batch: self.batch, seed_start: self.seed_start, shard: (0, 1) }
    }
}

impl RankConfig {
    /// The policies' names as the rows carry them: each checkpoint's folder name.
    #[must_use]
    pub fn policy_names(&self) -> Vec<String> {
        self.checkpoints.iter().map(|c| policies::dir::checkpoint_name(c)).collect()
    }
}

/// Reads a run's `config.json`.
///
/// # Errors
/// [`RunError::Io`] when it cannot be read, [`RunError::Parse`] naming the setting
/// where it stops being a `C`.
pub fn read<C: RunSettings>(path: &Path) -> Result<C, RunError> {
    read_typed(path, |field, source| RunError::Parse {
        path: path.to_path_buf(),
        what: C::KIND,
        field,
        source,
    })
}

/// Reads the JSON file `path` as a `T`; `bad(field, error)` is the error of a file that
/// parses as JSON but not as a `T`, or not at all, with the path of the field where it
/// stopped (`.` for the whole file).
///
/// # Errors
/// [`RunError::Io`] when the file cannot be read, else `bad`'s error.
pub(crate) fn read_typed<T: DeserializeOwned>(
    path: &Path,
    bad: impl FnOnce(String, serde_json::Error) -> RunError,
) -> Result<T, RunError> {
    let bytes = std::fs::read(path).map_err(|source| RunError::Io { path: path.to_path_buf(), source })?;
    let mut de = serde_json::Deserializer::from_slice(&bytes);
    serde_path_to_error::deserialize(&mut de).map_err(|e| bad(e.path().to_string(), e.into_inner()))
}

/// Writes a run's `config.json` (pretty, one trailing newline).
///
/// # Errors
/// [`RunError::Io`] when it cannot be written.
pub fn write<C: Serialize>(path: &Path, config: &C) -> Result<(), RunError> {
    let io = |source| RunError::Io { path: path.to_path_buf(), source };
    let mut text = serde_json::to_string_pretty(config).map_err(|e| io(std::io::Error::other(e)))?;
    text.push('\n');
    std::fs::write(path, text).map_err(io)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A small `rank` configuration: 100 episodes from seed 100 in batches of 50.
    pub(crate) fn rank_config() -> RankConfig {
        let wm: WorldModelConfig =
            serde_json::from_str(include_str!("../tests/fixtures/world_model_config.json")).unwrap();
        RankConfig {
            command: "evalharness rank".into(),
            scenario: "pusht".into(),
            scenario_parameters: None,
            policies: "set".into(),
            world_model: "wm".into(),
            world_model_config: wm,
            episodes: 100,
            seed_start: 100,
            max_steps: 300,
            batch: 50,
            seed: 0,
            bootstrap: 2000,
            shard: (0, 1),
            checkpoints: vec!["set/epoch-0001".into(), "set/epoch-0002".into()],
            fingerprints: [("world_model".to_string(), "sha256:aa".to_string())].into(),
            judge: None,
            judge_every_frame: false,
            float_frames: false,
            merged_from: Vec::new(),
        }
    }

    #[test]
    fn a_config_reads_back_as_written_and_unknown_settings_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("config.json");
        let c = rank_config();
        write(&path, &c).unwrap();
        assert_eq!(read::<RankConfig>(&path).unwrap(), c);
        // The flags written only when set are absent from a run without them.
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(!text.contains("judge_every_frame") && !text.contains("merged_from"), "{text}");
        let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
        v["planets"] = serde_json::json!(9);
        std::fs::write(&path, v.to_string()).unwrap();
        let err = read::<RankConfig>(&path).unwrap_err().to_string();
        assert!(err.contains("unknown field `planets`") && err.contains("--force"), "{err}");
        v.as_object_mut().unwrap().remove("planets");
        v["shard"] = serde_json::json!("0/1");
        std::fs::write(&path, v.to_string()).unwrap();
        let err = read::<RankConfig>(&path).unwrap_err().to_string();
        assert!(err.contains("(shard: invalid type"), "{err}");
    }

    #[test]
    fn a_plan_is_not_a_rank() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("config.json");
        write(&path, &rank_config()).unwrap();
        let err = read::<PlanConfig>(&path).unwrap_err().to_string();
        assert!(err.contains("not a plan run's config.json"), "{err}");
    }

    #[test]
    fn policy_names_are_the_folder_names() {
        assert_eq!(rank_config().policy_names(), ["epoch-0001", "epoch-0002"]);
    }
}
