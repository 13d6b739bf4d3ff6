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
//! configuration and the state rows (agent, block, goal).

use std::path::Path;

use anyhow::{Result, anyhow, bail};
use harness::replay::ReplayReader;
use rayon::prelude::*;
use scenarios::pusht::physics::PushTState;
use scenarios::pusht::render::Rasterizer;
use scenarios::pusht::{Pose2, PushTConfig};
use world_model::data::EpisodeData;

/// A dataset's scenario and state rows (`collect`'s 8 columns: agent x, y; block
/// x, y, θ; goal x, y, θ).
pub struct DatasetScene {
    /// The scenario the dataset was collected in.
    pub cfg: PushTConfig,
    state: Vec<f64>,
    dim: usize,
}

impl DatasetScene {
    /// Reads the scenario and the state rows of the dataset at `path`; `Ok(Err(why))`
    /// for a dataset without them (not collected by evalharness).
    ///
    /// # Errors
    /// An unreadable dataset or state array.
    pub fn load(path: &Path) -> Result<Result<Self, String>> {
        let r = ReplayReader::open(path)?;
        let cfg = match Self::from_attrs(&r.attrs) {
            Ok(cfg) => cfg,
            Err(why) => return Ok(Err(why)),
        };
        let dim = r.state.row_len();
        if dim < 8 {
            return Ok(Err(format!("data/state has {dim} columns, not the 8 with the goal")));
        }
        Ok(Ok(Self { cfg, state: r.state.read_f64()?, dim }))
    }

    /// The Push-T scenario a dataset's attributes record, or why there is none: no
    /// evalharness scenario at all, or another task's (whose scenes are not re-rendered).
    fn from_attrs(attrs: &serde_json::Value) -> Result<PushTConfig, String> {
        let eh = &attrs["evalharness"];
        match eh["scenario"].as_str() {
            Some(name) if name != "pusht" => {
                return Err(format!("the dataset's scenario is {name}; only Push-T scenes are re-rendered"));
            }
            _ => {}
        }
        serde_json::from_value::<PushTConfig>(eh["scenario_config"].clone())
            .map_err(|_| "the dataset records no evalharness scenario".to_string())
    }

    /// State rows.
    pub fn len(&self) -> usize {
        self.state.len() / self.dim
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

/// Replaces every frame of `data` (loaded from `path`) by the same scene rendered
/// without the goal; `loaded` is [`DatasetScene::load`]'s answer for `path`. Returns
/// the dataset's scene (for drawing the goals back).
///
/// # Errors
/// A dataset without evalharness's scenario and state, or whose state rows do not
/// match its frames.
pub fn strip_goal<'s>(
    path: &Path,
    loaded: &'s Result<DatasetScene, String>,
    data: &mut EpisodeData,
) -> Result<&'s DatasetScene> {
    let scene = loaded.as_ref().map_err(|why| {
        anyhow!(
            "{}: a goal-free world model needs frames re-rendered from the state, but {why}",
            path.display()
        )
    })?;
    if scene.len() != data.len() {
        bail!("{}: {} state rows for {} frames", path.display(), scene.len(), data.len());
    }
    let raster = Rasterizer::with_size(&scene.cfg, data.size);
    let n = raster.frame_len();
    data.frames.par_chunks_mut(n).enumerate().for_each(|(i, f)| {
        f.copy_from_slice(&raster.render_without_goal(&scene.state(i)));
    });
    Ok(scene)
}

#[cfg(test)]
mod tests {
    use clap::Parser;
    use scenarios::pusht::frame_score::FrameScorer;

    use super::*;
    use crate::cli::{Cli, Command};

    /// Regression: a Lift dataset was said to record no evalharness scenario.
    #[test]
    fn another_tasks_dataset_is_named_by_its_scenario() {
        let lift = serde_json::json!({"evalharness": {"scenario": "lift", "scenario_config": {}}});
        let why = DatasetScene::from_attrs(&lift).unwrap_err();
        assert_eq!(why, "the dataset's scenario is lift; only Push-T scenes are re-rendered");
        let none = serde_json::json!({});
        assert_eq!(
            DatasetScene::from_attrs(&none).unwrap_err(),
            "the dataset records no evalharness scenario"
        );
    }

    #[test]
    fn stripped_frames_are_the_scenes_without_their_goal() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.zarr");
        let p = path.to_str().unwrap();
        let args =
            ["evalharness", "-q", "collect", "--episodes", "2", "--max-steps", "12", "--mix", "explore=1"];
        let cli = Cli::try_parse_from([&args[..], &["--jobs", "1", "--out", p]].concat()).unwrap();
        let Command::Collect(c) = cli.command else { unreachable!() };
        super::super::collect::run(&c, true).unwrap();
        let mut data = EpisodeData::load(&path, 96).unwrap();
        let original = data.frames.clone();
        let loaded = DatasetScene::load(&path).unwrap();
        let scene = strip_goal(&path, &loaded, &mut data).unwrap();
        assert_eq!(scene.len(), data.len());
        let n = 96 * 96 * 3;
        for i in 0..data.len() {
            let (with, without) = (&original[i * n..(i + 1) * n], data.frame(i));
            assert!(!without.chunks_exact(3).any(|p| p == [0, 0, 0]), "frame {i}: goal pixels left");
            // Drawing the goal back gives the recorded frame (mean error below one grey
            // level: the state is stored as f32, and the goal's rim where the block or
            // agent crosses it is approximate). Wrong state columns would move the block
            // or the agent and fail this by far.
            let mut drawn = without.to_vec();
            FrameScorer::new(&scene.cfg, &scene.goal(i), 96).draw_goal(&mut drawn);
            let mean =
                with.iter().zip(&drawn).map(|(a, b)| f64::from(a.abs_diff(*b))).sum::<f64>() / n as f64;
            assert!(mean < 1.0, "frame {i}: mean |difference| {mean:.3}");
            assert!(with != without, "frame {i}: the goal was not removed");
        }
    }
}
