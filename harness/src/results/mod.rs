//! The typed results of a paired ranking run, shared by every crate that writes or
//! reads them: `rank` and `merge` write `results.json` and `episodes.jsonl` with
//! these types, `report` and the `reports` crate read them back.
//!
//! `results.json` is written through a [`serde_json::Value`], whose objects keep
//! their keys in sorted order, so the file's layout does not depend on the order of
//! the fields below. Reading names the field at fault
//! (`policies[2].sim.mean: invalid type: string "x", expected f64`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::judge::SceneCheck;
use crate::metrics::Agreement;
use crate::metrics::bootstrap::AgreementCi;
use crate::metrics::ceiling::NoiseCeiling;

mod legacy;
pub use crate::paired_success::PairedSuccess;

/// Which branch an episode ran in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Branch {
    /// The MuJoCo reference.
    Sim,
    /// The world model.
    WorldModel,
}

impl Branch {
    /// The name in every output file (`sim`, `world_model`).
    pub fn as_str(self) -> &'static str {
        match self {
            Branch::Sim => "sim",
            Branch::WorldModel => "world_model",
        }
    }
}

/// Named numbers of one episode that only its task defines, in key order (what a row's
/// [`EpisodeRow::state`] and [`EpisodeRow::scene`] hold).
pub type Named = BTreeMap<String, f64>;

/// One (policy, seed, branch) episode: a line of `episodes.jsonl`, a row of
/// `episodes.csv` and `episodes.parquet`. Task-neutral: the score, success and steps of
/// every task, and what only one task defines by name (Push-T's block and goal poses and
/// its scene checks) in [`EpisodeRow::state`] and [`EpisodeRow::scene`]. Rows written
/// before 2026-12-02 (`final_block`, `goal`, `block_area`, `goal_kept`, `agent_kept`,
/// `max_coverage`, `final_coverage`) are read into these fields ([`legacy`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(from = "legacy::RowOnDisk")]
pub struct EpisodeRow {
    /// Policy (checkpoint folder name).
    pub policy: String,
    /// Episode seed.
    pub seed: u64,
    /// Branch.
    pub branch: Branch,
    /// Max reward over the rollout (the task's raw score mapped to [0, 1], [`ScoreKind`]).
    ///
    /// [`ScoreKind`]: crate::task::ScoreKind
    pub score: f64,
    /// Max raw score over the rollout (Push-T: goal coverage; Lift and Can: 1 once
    /// the task's success holds, or a judge's success probability in imagination).
    pub max_raw: f64,
    /// Raw score at the last step.
    pub final_raw: f64,
    /// Whether the raw score ever exceeded the task's success threshold.
    pub success: bool,
    /// Control steps.
    pub steps: usize,
    /// Mean |judge's raw score − exact raw score| on this episode's real frames (MuJoCo rows
    /// of a task with a judge).
    pub scorer_abs_error: Option<f64>,
    /// Score so far (max reward) at the end of each action chunk.
    #[serde(default)]
    pub score_trace: Vec<f64>,
    /// The episode's conditions and final state, named by its task ([`Env::conditions`] on
    /// both branches, [`Env::final_state`] on MuJoCo rows; Push-T: `goal_x`, `goal_y`,
    /// `goal_theta`, and `final_block_x`, `final_block_y`, `final_block_theta`). Empty for a
    /// task that names none.
    ///
    /// [`Env::conditions`]: crate::task::Env::conditions
    /// [`Env::final_state`]: crate::task::Env::final_state
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub state: Named,
    /// The judge's scene checks of the last frame the policy saw ([`SceneCheck`]; Push-T:
    /// `block_area`, `goal_kept`, `agent_kept`): about 1 in MuJoCo; in the world model, how
    /// much of the scene its rollout kept. Empty where the judge makes none.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub scene: Named,
}

impl EpisodeRow {
    /// A row with the scores; success is `max_raw > thr`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        policy: &str,
        seed: u64,
        branch: Branch,
        score: f64,
        max_raw: f64,
        last_raw: f64,
        thr: f64,
        steps: usize,
    ) -> Self {
        Self {
            policy: policy.to_string(),
            seed,
            branch,
            score,
            max_raw,
            final_raw: last_raw,
            success: max_raw > thr,
            steps,
            scorer_abs_error: None,
            score_trace: Vec::new(),
            state: Named::new(),
            scene: Named::new(),
        }
    }

    /// With the score trace.
    pub fn with_trace(mut self, t: Vec<f64>) -> Self {
        self.score_trace = t;
        self
    }

    /// With named conditions or state of the episode (added to [`EpisodeRow::state`]).
    pub fn with_state(mut self, named: &[(&str, f64)]) -> Self {
        self.state.extend(named.iter().map(|&(k, v)| (k.to_string(), v)));
        self
    }

    /// With the frame scorer's error.
    pub fn with_scorer_error(mut self, e: Option<f64>) -> Self {
        self.scorer_abs_error = e;
        self
    }

    /// With the scene checks of the last frame the policy saw, or none.
    pub fn with_scene(mut self, checks: Option<&SceneCheck>) -> Self {
        self.scene =
            checks.map_or_else(Named::new, |c| c.0.iter().map(|&(k, v)| (k.to_string(), v)).collect());
        self
    }
}

/// One branch of one policy in `results.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(from = "legacy::BranchOnDisk")]
pub struct BranchStats {
    /// Mean episode score.
    pub mean: f64,
    /// Its bootstrap 95% interval (none for fewer than one episode).
    pub ci95: Option<[f64; 2]>,
    /// Fraction of successful episodes.
    pub success_rate: f64,
    /// Its Wilson 95% interval.
    pub success_ci95: [f64; 2],
    /// Mean control steps of the successful episodes: steps until the end of the
    /// action chunk in which the episode succeeded (it ends there); null when none did.
    #[serde(default)]
    pub steps_to_success: Option<f64>,
    /// Episodes.
    pub episodes: usize,
    /// Mean of each scene check over the rows that made it ([`EpisodeRow::scene`]; Push-T:
    /// `block_area`, `goal_kept`, `agent_kept`); empty where none did. Results of version 3
    /// and before held Push-T's three as fields of their own, read into this.
    #[serde(default)]
    pub scene: Named,
}

/// One policy in `results.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolicyResult {
    /// Checkpoint name.
    pub name: String,
    /// The MuJoCo branch.
    pub sim: BranchStats,
    /// The world-model branch.
    pub world_model: BranchStats,
    /// Mean frame-scorer error on the MuJoCo branch's real frames.
    pub frame_scorer_mean_abs_error: f64,
    /// Success of each seed's two episodes side by side (absent in results written
    /// before it was reported).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub paired_success: Option<PairedSuccess>,
}

/// How well the world model's scores agree with MuJoCo's across policies. Every
/// metric is null where undefined (fewer than two policies, constant scores).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AgreementSummary {
    /// Pearson r.
    pub pearson: Option<f64>,
    /// r², the coefficient of determination of the linear fit (what the official DriftWorld
    /// evaluation logs); absent in results written before it was reported.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pearson_r2: Option<f64>,
    /// Spearman ρ.
    pub spearman: Option<f64>,
    /// Kendall τ_b.
    pub kendall_tau_b: Option<f64>,
    /// Pairs ranked in the opposite order.
    pub rank_inversions: Option<usize>,
    /// Inversions over all pairs.
    pub rank_inversion_fraction: Option<f64>,
    /// Pairs tied in either ranking, by name.
    #[serde(default)]
    pub ties: Vec<[String; 2]>,
    /// Mean maximum rank violation.
    pub mmrv: Option<f64>,
    /// True score lost by picking the world model's best.
    pub regret_at_1: Option<f64>,
    /// Mean over policies of |world model's score − simulator's| (absent in results
    /// written before it was reported).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_abs_error: Option<f64>,
    /// Bootstrap 95% intervals of the metrics.
    pub ci95: Option<AgreementCi>,
    /// How well two independent MuJoCo runs of this size would agree: the best a world
    /// model can reach here (absent in results written before it, and below 2 policies).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_ceiling: Option<NoiseCeiling>,
}

/// A policy left out of the ranking, with why.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FailedPolicy {
    /// Checkpoint name.
    pub policy: String,
    /// The error.
    pub error: String,
}

/// Where a run's time went.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunTiming {
    /// Wall clock.
    pub wall_seconds: f64,
    /// MuJoCo stepping and rendering.
    pub sim_seconds: f64,
    /// World-model prediction and decoding.
    pub world_model_seconds: f64,
    /// World-model time per generated frame.
    pub world_model_ms_per_frame: f64,
    /// Policy inference.
    pub policy_seconds: f64,
    /// What the times cover.
    pub note: String,
}

/// The layout of `results.json` this build writes. Version 1 is the files written before
/// 2026-12-02, which have no `schema_version` and the same fields; version 2 added
/// `schema_version`; version 3 adds `scoring`, how the task scores an episode (absent, and
/// unknown to the report, in the earlier versions, which are still read); version 4 (2026-12-02)
/// keeps each branch's scene checks by name (`scene`) instead of Push-T's `block_area`,
/// `goal_kept` and `agent_kept` fields, which are still read. A file of a later version than
/// this is refused by name rather than read as one of this version.
pub const RESULTS_SCHEMA: u32 = 4;

/// The version a `results.json` without `schema_version` was written in.
fn first_schema() -> u32 {
    1
}

/// `results.json` of `rank` and `merge`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RankResults {
    /// The file's layout ([`RESULTS_SCHEMA`] when written by this build; 1 when absent).
    #[serde(default = "first_schema")]
    pub schema_version: u32,
    /// Scenario name or file.
    pub scenario: String,
    /// World-model folder.
    pub world_model: PathBuf,
    /// Episodes per policy.
    pub episodes: usize,
    /// First episode seed.
    pub seed_start: u64,
    /// Control steps per episode.
    pub max_steps: usize,
    /// How the task scores an episode ([`crate::task::ScoreKind::describe`]); from version 3.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scoring: Option<String>,
    /// The reference simulator's name ([`crate::task::Task::simulator`]); absent, as in files
    /// written before 2026-12-03, means MuJoCo.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulator: Option<String>,
    /// Ranked policies, in run order.
    pub policies: Vec<PolicyResult>,
    /// Agreement across them.
    pub agreement: AgreementSummary,
    /// Policies left out.
    #[serde(default)]
    pub failed_policies: Vec<FailedPolicy>,
    /// Timing.
    pub timing: RunTiming,
}

/// A `results.json` that cannot be read or written.
#[derive(Debug, thiserror::Error)]
pub enum ResultsError {
    /// I/O on the file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Not JSON, or a field missing or of the wrong type (by its path).
    #[error("{path}: not a complete evalharness rank results file: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The field's path and what is wrong with it.
        message: String,
    },
    /// Written by a later evalharness, in a layout this build does not know.
    #[error(
        "{path}: results schema version {found}, written by a later evalharness; this one reads versions 1 to {RESULTS_SCHEMA}"
    )]
    Newer {
        /// The file.
        path: PathBuf,
        /// Its `schema_version`.
        found: u32,
    },
}

impl RankResults {
    /// The reference simulator's name: the recorded one, else MuJoCo's.
    pub fn simulator(&self) -> &str {
        self.simulator.as_deref().unwrap_or("MuJoCo")
    }

    /// Reads `path`, naming the first field that is missing or of the wrong type.
    ///
    /// # Errors
    /// [`ResultsError`] naming the file (and the field).
    pub fn read(path: &Path) -> Result<Self, ResultsError> {
        let text =
            std::fs::read_to_string(path).map_err(|source| ResultsError::Io { path: path.into(), source })?;
        /// The version alone, read first: a later layout may not parse as this one.
        #[derive(Deserialize)]
        struct Version {
            #[serde(default = "first_schema")]
            schema_version: u32,
        }
        if let Ok(Version { schema_version: found }) = serde_json::from_str(&text)
            && found > RESULTS_SCHEMA
        {
            return Err(ResultsError::Newer { path: path.into(), found });
        }
        let de = &mut serde_json::Deserializer::from_str(&text);
        serde_path_to_error::deserialize(de).map_err(|e| {
            let field = e.path().to_string();
            let message =
                if field == "." { e.inner().to_string() } else { format!("{field}: {}", e.inner()) };
            ResultsError::Invalid { path: path.into(), message }
        })
    }

    /// The JSON document, its objects' keys in sorted order.
    ///
    /// # Errors
    /// Never for these types (serde_json's error is passed on all the same).
    pub fn to_json(&self) -> Result<serde_json::Value, serde_json::Error> {
        serde_json::to_value(self)
    }
}

/// The typed form of the agreement metrics (here, so that `metrics` never needs
/// `results`).
impl Agreement {
    /// The `agreement` of `agreement` and `rank` outputs: every metric, tied pairs by
    /// name (`names[i]` is policy i) and the 95% intervals. A ranking of fewer than
    /// two policies has no pairs: its inversion count, MMRV and regret are undefined,
    /// not perfect (null, like the correlations).
    pub fn summary(&self, names: &[&str], ci: Option<&AgreementCi>) -> AgreementSummary {
        let ranked = names.len() >= 2;
        AgreementSummary {
            pearson: self.pearson,
            pearson_r2: self.pearson.map(|r| r * r),
            spearman: self.spearman,
            kendall_tau_b: self.kendall_tau_b,
            rank_inversions: ranked.then_some(self.rank_inversions.count),
            rank_inversion_fraction: ranked.then_some(self.rank_inversions.fraction),
            ties: self
                .rank_inversions
                .ties
                .iter()
                .map(|&(i, j)| [names[i].to_string(), names[j].to_string()])
                .collect(),
            mmrv: ranked.then_some(self.mmrv),
            regret_at_1: ranked.then_some(self.regret_at_1),
            mean_abs_error: (!names.is_empty()).then_some(self.mean_abs_error),
            ci95: ci.cloned(),
            noise_ceiling: None,
        }
    }

    /// [`Agreement::summary`] as JSON.
    pub fn to_json(&self, names: &[&str], ci: Option<&AgreementCi>) -> serde_json::Value {
        serde_json::to_value(self.summary(names, ci)).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> serde_json::Value {
        let branch = serde_json::json!({"mean": 0.5, "ci95": [0.4, 0.6], "success_rate": 0.5,
            "success_ci95": [0.1, 0.9], "steps_to_success": 12.5, "episodes": 2, "block_area": null,
            "goal_kept": null, "agent_kept": 1.0});
        serde_json::json!({
            "schema_version": 2, "scenario": "pusht", "world_model": "wm", "episodes": 2, "seed_start": 5, "max_steps": 300,
            "policies": [{"name": "a", "sim": branch, "world_model": branch, "frame_scorer_mean_abs_error": 0.01}],
            "agreement": {"pearson": null, "spearman": null, "kendall_tau_b": null, "rank_inversions": null,
                "rank_inversion_fraction": null, "ties": [], "mmrv": null, "regret_at_1": null, "ci95": null},
            "failed_policies": [{"policy": "c", "error": "bad"}],
            "timing": {"wall_seconds": 1.0, "sim_seconds": 0.5, "world_model_seconds": 0.25,
                "world_model_ms_per_frame": 4.0, "policy_seconds": 0.1, "note": "n"},
        })
    }

    #[test]
    fn reads_the_previous_version_and_refuses_a_later_one() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("results.json");
        // Version 2: no scoring; version 1: no schema_version either.
        std::fs::write(&path, sample().to_string()).unwrap();
        let v2 = RankResults::read(&path).unwrap();
        assert_eq!((v2.schema_version, v2.scoring), (2, None));
        let mut v1 = sample();
        v1.as_object_mut().unwrap().remove("schema_version");
        std::fs::write(&path, v1.to_string()).unwrap();
        assert_eq!(RankResults::read(&path).unwrap().schema_version, 1);
        // Version 3 names the scoring.
        let mut v3 = sample();
        v3["schema_version"] = serde_json::json!(3);
        v3["scoring"] = serde_json::json!("1 if the task succeeded at some step, else 0");
        std::fs::write(&path, v3.to_string()).unwrap();
        let scoring = RankResults::read(&path).unwrap().scoring;
        assert_eq!(scoring.as_deref(), Some("1 if the task succeeded at some step, else 0"));
        // A later version is named, whatever else it holds.
        let later = serde_json::json!({"schema_version": RESULTS_SCHEMA + 1, "rows": "elsewhere"});
        std::fs::write(&path, later.to_string()).unwrap();
        let err = RankResults::read(&path).unwrap_err().to_string();
        assert!(err.contains("results schema version 5, written by a later evalharness"), "{err}");
        assert!(err.contains("reads versions 1 to 4") && err.contains("results.json"), "{err}");
    }

    #[test]
    fn round_trips_and_names_a_damaged_field() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("results.json");
        std::fs::write(&path, sample().to_string()).unwrap();
        let r = RankResults::read(&path).unwrap();
        let again = dir.path().join("again.json");
        std::fs::write(&again, r.to_json().unwrap().to_string()).unwrap();
        assert_eq!(RankResults::read(&again).unwrap(), r);
        // A results.json written before steps to success were recorded still reads (null).
        let mut old = sample();
        old["policies"][0]["sim"].as_object_mut().unwrap().remove("steps_to_success");
        std::fs::write(&path, old.to_string()).unwrap();
        assert_eq!(RankResults::read(&path).unwrap().policies[0].sim.steps_to_success, None);
        let mut bad = sample();
        bad["policies"][0]["sim"]["mean"] = serde_json::json!("high");
        std::fs::write(&path, bad.to_string()).unwrap();
        let err = RankResults::read(&path).unwrap_err().to_string();
        assert!(err.contains("policies[0].sim.mean: invalid type: string \"high\", expected f64"), "{err}");
        let mut bad = sample();
        bad.as_object_mut().unwrap().remove("agreement");
        std::fs::write(&path, bad.to_string()).unwrap();
        let err = RankResults::read(&path).unwrap_err().to_string();
        assert!(err.contains("missing field `agreement`"), "{err}");
    }
}
