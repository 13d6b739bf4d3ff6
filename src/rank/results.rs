//! Episode rows and the statistics computed from them.
//!
//! `episodes.jsonl` is the source of truth: rows are appended as batches finish,
//! `--resume` reads them back to skip finished episodes, `merge` concatenates
//! shards' rows, and `results.json` is always recomputed from the (sorted) rows,
//! so a resumed, sharded or multi-threaded run gives the same results as one
//! uninterrupted run.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

use anyhow::{Context, Result};
use harness::metrics::agreement;
use harness::metrics::bootstrap::{agreement_ci, mean_ci, wilson};
use scenarios::pusht::frame_score::SceneCheck;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

/// Which branch a row comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
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

/// One (policy, seed, branch) episode.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EpisodeRow {
    /// Policy (checkpoint folder name).
    pub policy: String,
    /// Episode seed.
    pub seed: u64,
    /// Branch.
    pub branch: Branch,
    /// Max reward over the rollout (clip(coverage / threshold, 0, 1)).
    pub score: f64,
    /// Max coverage over the rollout.
    pub max_coverage: f64,
    /// Coverage at the last step.
    pub final_coverage: f64,
    /// Whether the coverage ever exceeded the success threshold.
    pub success: bool,
    /// Control steps.
    pub steps: usize,
    /// Final block pose (x, y, θ); the world-model branch has none.
    pub final_block: Option<[f64; 3]>,
    /// Goal pose.
    pub goal: [f64; 3],
    /// Mean |frame-scorer coverage − exact coverage| on this episode's real frames (MuJoCo rows).
    pub scorer_abs_error: Option<f64>,
    /// Score so far (max reward) at the end of each action chunk.
    #[serde(default)]
    pub score_trace: Vec<f64>,
    /// Block pixels in the last frame the policy saw, as a fraction of the T's area
    /// ([`scenarios::pusht::frame_score::FrameScorer::block_area`]): ≈ 1 in MuJoCo;
    /// in the world model, how much of the block its rollout kept. Absent in runs
    /// written before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub block_area: Option<f64>,
    /// How much of the (static) goal T that frame still shows
    /// ([`scenarios::pusht::frame_score::FrameScorer::goal_kept`]): ≈ 0.94–0.99 in
    /// MuJoCo; lower when an imagined scene has faded or eroded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal_kept: Option<f64>,
    /// Agent pixels in that frame as a fraction of the agent disk's area, capped at 1
    /// ([`scenarios::pusht::frame_score::FrameScorer::agent_kept`]): ≈ 1 in MuJoCo;
    /// near 0 when an imagined rollout lost the agent. Absent in older runs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub agent_kept: Option<f64>,
}

impl EpisodeRow {
    /// A row with the scores.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        policy: &str,
        seed: u64,
        branch: Branch,
        score: f64,
        max_cov: f64,
        last_cov: f64,
        thr: f64,
        steps: usize,
    ) -> Self {
        Self {
            policy: policy.to_string(),
            seed,
            branch,
            score,
            max_coverage: max_cov,
            final_coverage: last_cov,
            success: max_cov > thr,
            steps,
            final_block: None,
            goal: [0.0; 3],
            scorer_abs_error: None,
            score_trace: Vec::new(),
            block_area: None,
            goal_kept: None,
            agent_kept: None,
        }
    }

    /// With the scene checks of the last seen frame.
    pub fn with_scene(mut self, scene: Option<SceneCheck>) -> Self {
        self.block_area = scene.map(|s| s.block_area);
        self.goal_kept = scene.map(|s| s.goal_kept);
        self.agent_kept = scene.map(|s| s.agent_kept);
        self
    }

    /// With the score trace.
    pub fn with_trace(mut self, t: Vec<f64>) -> Self {
        self.score_trace = t;
        self
    }

    /// With the final block and the goal pose.
    pub fn with_poses(mut self, block: Option<[f64; 3]>, goal: [f64; 3]) -> Self {
        self.final_block = block;
        self.goal = goal;
        self
    }

    /// With the frame scorer's error.
    pub fn with_scorer_error(mut self, e: Option<f64>) -> Self {
        self.scorer_abs_error = e;
        self
    }
}

/// Reads `episodes.jsonl` (missing file: no rows).
///
/// # Errors
/// An unreadable file or a malformed line, naming the file and line.
pub fn read_rows<T: serde::de::DeserializeOwned>(path: &Path) -> Result<Vec<T>> {
    if !path.exists() {
        return Ok(Vec::new());
    }
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str(l).with_context(|| format!("{} line {}: invalid row", path.display(), i + 1))
        })
        .collect()
}

/// Appends rows (of `rank` or `plan`) to an `episodes.jsonl`, synced, so a killed run keeps its finished batches.
///
/// # Errors
/// I/O failures naming the file.
pub fn append_rows<T: Serialize>(path: &Path, rows: &[T]) -> Result<()> {
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)
        .with_context(|| format!("opening {}", path.display()))?;
    let mut text = String::new();
    for r in rows {
        text.push_str(&serde_json::to_string(r)?);
        text.push('\n');
    }
    f.write_all(text.as_bytes())
        .and_then(|()| f.sync_data())
        .with_context(|| format!("writing {}", path.display()))
}

/// Mean, bootstrap CI, success rate and Wilson CI of one branch of one policy.
pub fn branch_stats(rows: &[&EpisodeRow], bootstrap: usize, seed: u64) -> Value {
    let scores: Vec<f64> = rows.iter().map(|r| r.score).collect();
    let n = scores.len();
    let k = rows.iter().filter(|r| r.success).count();
    let mean_of = |v: Vec<f64>| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
    json!({
        "mean": scores.iter().sum::<f64>() / n.max(1) as f64,
        "ci95": mean_ci(&scores, bootstrap, seed),
        "success_rate": k as f64 / n.max(1) as f64,
        "success_ci95": wilson(k, n, 1.959_963_984_540_054),
        "episodes": n,
        "block_area": mean_of(rows.iter().filter_map(|r| r.block_area).collect()),
        "goal_kept": mean_of(rows.iter().filter_map(|r| r.goal_kept).collect()),
        "agent_kept": mean_of(rows.iter().filter_map(|r| r.agent_kept).collect()),
    })
}

/// Per-policy statistics and agreement, from rows (any order; sorted here).
/// `policies` fixes the output order; policies without complete pairs are skipped.
pub fn summarise(rows: &[EpisodeRow], policies: &[String], bootstrap: usize, seed: u64) -> Value {
    let mut by: BTreeMap<(&str, u64), [Option<&EpisodeRow>; 2]> = BTreeMap::new();
    for r in rows {
        let e = by.entry((r.policy.as_str(), r.seed)).or_default();
        e[usize::from(r.branch == Branch::WorldModel)] = Some(r);
    }
    let mut out = Vec::new();
    let mut pairs: Vec<(Vec<f64>, Vec<f64>)> = Vec::new();
    let mut names = Vec::new();
    for p in policies {
        let eps: Vec<[&EpisodeRow; 2]> = by
            .range((p.as_str(), 0)..=(p.as_str(), u64::MAX))
            .filter_map(|(_, v)| Some([v[0]?, v[1]?]))
            .collect();
        if eps.is_empty() {
            continue;
        }
        let sim: Vec<&EpisodeRow> = eps.iter().map(|e| e[0]).collect();
        let wm: Vec<&EpisodeRow> = eps.iter().map(|e| e[1]).collect();
        let errs: Vec<f64> = sim.iter().filter_map(|r| r.scorer_abs_error).collect();
        out.push(json!({
            "name": p,
            "sim": branch_stats(&sim, bootstrap, seed),
            "world_model": branch_stats(&wm, bootstrap, seed),
            "frame_scorer_mean_abs_error": errs.iter().sum::<f64>() / errs.len().max(1) as f64,
        }));
        pairs.push((wm.iter().map(|r| r.score).collect(), sim.iter().map(|r| r.score).collect()));
        names.push(p.as_str());
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let pred: Vec<f64> = pairs.iter().map(|(w, _)| mean(w)).collect();
    let act: Vec<f64> = pairs.iter().map(|(_, s)| mean(s)).collect();
    let m = agreement(&pred, &act);
    let ci = (pairs.len() >= 2 && pairs.iter().all(|(w, _)| w.len() >= 2))
        .then(|| agreement_ci(&pairs, bootstrap, seed));
    json!({"policies": out, "agreement": m.to_json(&names, ci.as_ref())})
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(p: &str, seed: u64, b: Branch, score: f64) -> EpisodeRow {
        EpisodeRow::new(p, seed, b, score, score * 0.95, 0.0, 0.95, 10)
    }

    #[test]
    fn summary_pairs_branches_and_computes_agreement() {
        // Policy a: sim (0.2, 0.4) mean 0.3, wm (0.1, 0.3) mean 0.2;
        // policy b: sim (0.8, 1.0) mean 0.9, wm (0.7, 0.9) mean 0.8. Same order: r = 1, no inversion.
        let rows = vec![
            row("b", 2, Branch::WorldModel, 0.9),
            row("a", 1, Branch::Sim, 0.2),
            row("a", 1, Branch::WorldModel, 0.1),
            row("a", 2, Branch::Sim, 0.4),
            row("a", 2, Branch::WorldModel, 0.3),
            row("b", 1, Branch::Sim, 0.8),
            row("b", 1, Branch::WorldModel, 0.7),
            row("b", 2, Branch::Sim, 1.0),
            row("a", 3, Branch::Sim, 0.9), // unpaired: ignored
        ];
        let s = summarise(&rows, &["a".into(), "b".into()], 200, 0);
        assert!((s["policies"][0]["sim"]["mean"].as_f64().unwrap() - 0.3).abs() < 1e-12);
        assert!((s["policies"][1]["world_model"]["mean"].as_f64().unwrap() - 0.8).abs() < 1e-12);
        // Success: max coverage = 0.95 score > 0.95 only for score 1.0 (0.95 > 0.95 is false): none.
        assert_eq!(s["policies"][1]["sim"]["success_rate"].as_f64(), Some(0.0));
        assert!((s["agreement"]["pearson"].as_f64().unwrap() - 1.0).abs() < 1e-12);
        assert_eq!(s["agreement"]["rank_inversions"].as_u64(), Some(0));
        // No scene checks recorded (as in runs made before they existed): null.
        assert_eq!(s["policies"][0]["sim"]["block_area"], Value::Null);
        // Same input in another order gives the same summary.
        let mut rev = rows.clone();
        rev.reverse();
        assert_eq!(summarise(&rev, &["a".into(), "b".into()], 200, 0), s);
    }
}
