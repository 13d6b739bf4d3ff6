//! The layouts of `episodes.jsonl` rows and `results.json` branches written before
//! 2026-12-02, read into this build's types: Push-T's final block and goal poses and its scene
//! checks (`final_block`, `goal`, `block_area`, `goal_kept`, `agent_kept`) were fields of every
//! row and branch, and a row's raw scores were `max_coverage` and `final_coverage`. Now a
//! task names its own ([`EpisodeRow::state`], [`EpisodeRow::scene`], [`BranchStats::scene`]),
//! so an older run still resumes, merges and reports.

use serde::Deserialize;

use super::{Branch, BranchStats, EpisodeRow, Named};

/// An `episodes.jsonl` line as read: this build's fields, and those of rows written before
/// the task-specific ones moved into [`EpisodeRow::state`] and [`EpisodeRow::scene`].
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RowOnDisk {
    policy: String,
    seed: u64,
    branch: Branch,
    score: f64,
    #[serde(alias = "max_coverage")]
    max_raw: f64,
    #[serde(alias = "final_coverage")]
    final_raw: f64,
    success: bool,
    steps: usize,
    scorer_abs_error: Option<f64>,
    #[serde(default)]
    score_trace: Vec<f64>,
    #[serde(default)]
    state: Named,
    #[serde(default)]
    scene: Named,
    /// Before 2026-12-02: Push-T's final block pose (null in the world model).
    #[serde(default)]
    final_block: Option<[f64; 3]>,
    /// Before 2026-12-02: the goal pose (zeros for a task without one).
    #[serde(default)]
    goal: Option<[f64; 3]>,
    #[serde(default)]
    block_area: Option<f64>,
    #[serde(default)]
    goal_kept: Option<f64>,
    #[serde(default)]
    agent_kept: Option<f64>,
}

impl From<RowOnDisk> for EpisodeRow {
    fn from(r: RowOnDisk) -> Self {
        let (mut state, mut scene) = (r.state, r.scene);
        for (prefix, pose) in [("final_block", r.final_block), ("goal", r.goal)] {
            for (k, v) in ["x", "y", "theta"].into_iter().zip(pose.into_iter().flatten()) {
                state.insert(format!("{prefix}_{k}"), v);
            }
        }
        let old = [("block_area", r.block_area), ("goal_kept", r.goal_kept), ("agent_kept", r.agent_kept)];
        scene.extend(old.into_iter().filter_map(|(k, v)| Some((k.to_string(), v?))));
        Self {
            policy: r.policy,
            seed: r.seed,
            branch: r.branch,
            score: r.score,
            max_raw: r.max_raw,
            final_raw: r.final_raw,
            success: r.success,
            steps: r.steps,
            scorer_abs_error: r.scorer_abs_error,
            score_trace: r.score_trace,
            state,
            scene,
        }
    }
}

/// A branch's statistics as read: this build's, or those of version 3 and before with
/// Push-T's scene checks as fields of their own.
#[derive(Deserialize)]
pub(crate) struct BranchOnDisk {
    mean: f64,
    ci95: Option<[f64; 2]>,
    success_rate: f64,
    success_ci95: [f64; 2],
    #[serde(default)]
    steps_to_success: Option<f64>,
    episodes: usize,
    #[serde(default)]
    scene: Named,
    #[serde(default)]
    block_area: Option<f64>,
    #[serde(default)]
    goal_kept: Option<f64>,
    #[serde(default)]
    agent_kept: Option<f64>,
}

impl From<BranchOnDisk> for BranchStats {
    fn from(b: BranchOnDisk) -> Self {
        let mut scene = b.scene;
        let old = [("block_area", b.block_area), ("goal_kept", b.goal_kept), ("agent_kept", b.agent_kept)];
        scene.extend(old.into_iter().filter_map(|(k, v)| Some((k.to_string(), v?))));
        Self {
            mean: b.mean,
            ci95: b.ci95,
            success_rate: b.success_rate,
            success_ci95: b.success_ci95,
            steps_to_success: b.steps_to_success,
            episodes: b.episodes,
            scene,
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::results::{BranchStats, EpisodeRow, Named};

    #[test]
    fn reads_version_3_scene_fields_into_named_checks() {
        // A branch of a version-3 results.json: Push-T's checks as fields, one of them null.
        let v3 = serde_json::json!({"mean": 0.5, "ci95": [0.4, 0.6], "success_rate": 0.5,
            "success_ci95": [0.1, 0.9], "steps_to_success": 12.5, "episodes": 2, "block_area": null,
            "goal_kept": 0.9, "agent_kept": 1.0});
        let b: BranchStats = serde_json::from_value(v3).unwrap();
        let want: Named = [("agent_kept".to_string(), 1.0), ("goal_kept".to_string(), 0.9)].into();
        assert_eq!((&b.scene, b.episodes), (&want, 2));
        // Written back in this build's layout: the named map, not the old fields.
        let json = serde_json::to_value(&b).unwrap();
        assert_eq!(json["scene"], serde_json::json!({"agent_kept": 1.0, "goal_kept": 0.9}));
        assert!(json.get("block_area").is_none() && json.get("goal_kept").is_none());
    }

    #[test]
    fn reads_rows_written_before_the_task_specific_fields_moved() {
        // A Push-T MuJoCo row as written before 2026-12-02.
        let old = r#"{"policy":"p","seed":3,"branch":"sim","score":0.5,"max_coverage":0.6,"final_coverage":0.4,
            "success":false,"steps":10,"final_block":[1.0,2.0,0.5],"goal":[3.0,4.0,0.1],"scorer_abs_error":0.01,
            "score_trace":[0.5],"block_area":0.98,"goal_kept":0.95,"agent_kept":0.99}"#;
        let r: EpisodeRow = serde_json::from_str(old).unwrap();
        assert_eq!((r.max_raw, r.final_raw, r.steps), (0.6, 0.4, 10));
        let keys: Vec<&str> = r.state.keys().map(String::as_str).collect();
        let want = ["final_block_theta", "final_block_x", "final_block_y", "goal_theta", "goal_x", "goal_y"];
        assert_eq!(keys, want);
        assert_eq!((r.state["final_block_y"], r.state["goal_theta"]), (2.0, 0.1));
        assert_eq!((r.scene.len(), r.scene["goal_kept"]), (3, 0.95));
        // Written and read again in this build's layout: the same row.
        let line = serde_json::to_string(&r).unwrap();
        assert!(line.contains("\"max_raw\":0.6") && !line.contains("final_block\""), "{line}");
        assert_eq!(serde_json::from_str::<EpisodeRow>(&line).unwrap(), r);
        // A world-model row of a task without checks has neither map; an unknown field is refused.
        let wm = r#"{"policy":"p","seed":3,"branch":"world_model","score":0.0,"max_raw":0.0,"final_raw":0.0,
            "success":false,"steps":1,"scorer_abs_error":null}"#;
        let r: EpisodeRow = serde_json::from_str(wm).unwrap();
        assert!(r.state.is_empty() && r.scene.is_empty());
        assert!(!serde_json::to_string(&r).unwrap().contains("scene"));
        let err = serde_json::from_str::<EpisodeRow>(&wm.replace("\"steps\"", "\"stepz\"")).unwrap_err();
        assert!(err.to_string().contains("unknown field `stepz`"), "{err}");
    }
}
