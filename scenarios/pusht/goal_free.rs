//! Goal-free frames, for world models trained with `train world-model --goal-free`.
//!
//! Push-T's goal T never moves and is known from each episode's initial state, so
//! a world model need not predict it. A goal-free model is trained on frames
//! re-rendered without it, and its users hand it goal-free frames and draw the goal
//! back onto what it generates (`FrameScorer::draw_goal`) before a policy or a
//! scorer sees them. The point: a model that sees the goal learns the expert data's
//! "blocks go to the goal" prior and, over a long rollout, drifts any block there
//! (measured in BENCHMARKS.md, 2026-11-24); one that never sees it cannot.
//!
//! Re-rendering needs what evalharness records with every dataset: the scenario's
//! configuration (read here as a typed view of the dataset's attributes) and the
//! state rows (agent, block, goal).

use std::path::{Path, PathBuf};

use harness::replay::attrs::DatasetAttrs;
use harness::replay::{ReplayError, ReplayReader};
use rayon::prelude::*;

use super::physics::PushTState;
use super::render::Rasterizer;
use super::{Pose2, PushTConfig};

/// Why a dataset has no Push-T scene to re-render (an answer, not a failure: `wm eval`
/// then skips what needs one).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum NoScene {
    /// Another task's dataset.
    #[error("the dataset's scenario is {0}; only Push-T scenes are re-rendered")]
    OtherTask(String),
    /// No evalharness scenario in the attributes (another codebase's dataset).
    #[error("the dataset records no evalharness scenario")]
    Unrecorded,
    /// State rows without the goal's columns.
    #[error("data/state has {0} columns, not the 8 with the goal")]
    FewColumns(usize),
}

/// A goal-free input that cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum GoalFreeError {
    /// The dataset or its state rows could not be read.
    #[error(transparent)]
    Replay(#[from] ReplayError),
    /// The dataset has no scene to re-render.
    #[error("{}: a goal-free world model needs frames re-rendered from the state, but {why}", path.display())]
    NoScene {
        /// The dataset.
        path: PathBuf,
        /// Why not.
        why: NoScene,
    },
    /// The state rows and the frames disagree in number.
    #[error("{}: {rows} state rows for {frames} frames", path.display())]
    Rows {
        /// The dataset.
        path: PathBuf,
        /// State rows.
        rows: usize,
        /// Frames.
        frames: usize,
    },
}

/// A dataset's scenario and state rows (`collect`'s 8 columns: agent x, y; block
/// x, y, θ; goal x, y, θ).
#[derive(Debug)]
pub struct DatasetScene {
    /// The scenario the dataset was collected in.
    pub cfg: PushTConfig,
    state: Vec<f64>,
    dim: usize,
}

impl DatasetScene {
    /// Reads the scenario and the state rows of the dataset at `path`; `Ok(Err(why))`
    /// for a dataset without them (not collected by evalharness, or another task's).
    ///
    /// # Errors
    /// An unreadable dataset, attributes or state array.
    pub fn load(path: &Path) -> Result<Result<Self, NoScene>, ReplayError> {
        let r = ReplayReader::open(path)?;
        let cfg = match Self::from_attrs(DatasetAttrs::from_root(path, &r.attrs)?) {
            Ok(cfg) => cfg,
            Err(why) => return Ok(Err(why)),
        };
        let dim = r.state.row_len();
        if dim < 8 {
            return Ok(Err(NoScene::FewColumns(dim)));
        }
        Ok(Ok(Self { cfg, state: r.state.read_f64()?, dim }))
    }

    /// The Push-T scenario a dataset's attributes record, or why there is none: no
    /// evalharness scenario at all, or another task's (whose scenes are not re-rendered).
    fn from_attrs(attrs: Option<DatasetAttrs>) -> Result<PushTConfig, NoScene> {
        let Some(recorded) = attrs else {
            return Err(NoScene::Unrecorded);
        };
        if let Some(name) = recorded.scenario.filter(|n| n != "pusht") {
            return Err(NoScene::OtherTask(name));
        }
        recorded
            .scenario_config
            .and_then(|c| serde_json::from_value::<PushTConfig>(c).ok())
            .ok_or(NoScene::Unrecorded)
    }

    /// State rows.
    pub fn len(&self) -> usize {
        self.state.len() / self.dim
    }

    /// Whether there are no state rows.
    pub fn is_empty(&self) -> bool {
        self.state.is_empty()
    }

    /// The goal pose at step `i`.
    pub fn goal(&self, i: usize) -> Pose2 {
        let s = &self.state[i * self.dim..];
        Pose2::new(s[5], s[6], s[7])
    }

    /// The agent and block at step `i` (the agent's velocity, which no frame shows, is 0).
    pub fn state(&self, i: usize) -> PushTState {
        let s = &self.state[i * self.dim..];
        PushTState { agent: [s[0], s[1]], agent_vel: [0.0; 2], block: Pose2::new(s[2], s[3], s[4]) }
    }
}

/// Replaces every `size`² RGB frame of `frames` (the dataset at `path`, frames back to
/// back) by the same scene rendered without the goal; `loaded` is [`DatasetScene::load`]'s
/// answer for `path`. Returns the dataset's scene (for drawing the goals back).
///
/// # Errors
/// A dataset without evalharness's scenario and state, or whose state rows do not
/// match its frames.
pub fn strip_goal<'s>(
    path: &Path,
    loaded: &'s Result<DatasetScene, NoScene>,
    frames: &mut [u8],
    size: usize,
) -> Result<&'s DatasetScene, GoalFreeError> {
    let scene = loaded
        .as_ref()
        .map_err(|why| GoalFreeError::NoScene { path: path.to_path_buf(), why: why.clone() })?;
    let raster = Rasterizer::with_size(&scene.cfg, size);
    let n = raster.frame_len();
    let count = frames.len() / n.max(1);
    if scene.len() != count {
        return Err(GoalFreeError::Rows { path: path.to_path_buf(), rows: scene.len(), frames: count });
    }
    frames.par_chunks_mut(n).enumerate().for_each(|(i, f)| {
        f.copy_from_slice(&raster.render_without_goal(&scene.state(i)));
    });
    Ok(scene)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Regression: a Lift dataset was said to record no evalharness scenario.
    #[test]
    fn another_tasks_dataset_is_named_by_its_scenario() {
        let read = |v: serde_json::Value| DatasetAttrs::from_root(Path::new("d.zarr"), &v).unwrap();
        let lift = serde_json::json!({"evalharness": {"scenario": "lift", "scenario_config": {}}});
        let why = DatasetScene::from_attrs(read(lift)).unwrap_err();
        assert_eq!(why.to_string(), "the dataset's scenario is lift; only Push-T scenes are re-rendered");
        let none = serde_json::json!({});
        assert_eq!(
            DatasetScene::from_attrs(read(none)).unwrap_err().to_string(),
            "the dataset records no evalharness scenario"
        );
        let pusht = serde_json::json!({"evalharness": {"scenario": "pusht",
            "scenario_config": serde_json::to_value(PushTConfig::default()).unwrap()}});
        assert_eq!(DatasetScene::from_attrs(read(pusht)).unwrap(), PushTConfig::default());
    }

    #[test]
    fn frames_and_state_rows_must_agree_in_number() {
        let scene = DatasetScene { cfg: PushTConfig::default(), state: vec![0.0; 8 * 3], dim: 8 };
        let loaded = Ok(scene);
        let mut frames = vec![0u8; 2 * 16 * 16 * 3];
        let e = strip_goal(Path::new("d.zarr"), &loaded, &mut frames, 16).unwrap_err();
        assert_eq!(e.to_string(), "d.zarr: 3 state rows for 2 frames");
        let none = Err(NoScene::FewColumns(5));
        let e = strip_goal(Path::new("d.zarr"), &none, &mut frames, 16).unwrap_err();
        assert_eq!(
            e.to_string(),
            "d.zarr: a goal-free world model needs frames re-rendered from the state, but data/state has 5 columns, not the 8 with the goal"
        );
    }
}
