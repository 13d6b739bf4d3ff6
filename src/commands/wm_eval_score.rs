//! `wm eval`'s open-loop score check: how far the Push-T score read from a model's
//! whole-episode rollouts is from the score of the real frames they replace.
//!
//! Why: `rank` ranks policies by scores read from imagined frames, and video
//! metrics (SSIM, PSNR) do not say whether the block ends up where it really went.
//! Here the model replays the episode's recorded actions from 4 real frames (no
//! policy in the loop), and both the generated and the real frames after the
//! context are scored by the same frame scorer against the episode's goal (from
//! the dataset's goal columns): score = max over frames of clip(coverage / 0.95,
//! 0, 1), as in `rank`. On datasets of policy rollouts (`collect --policy`) this
//! shows, without the closed loop, whether a model follows what weak policies do.

use anyhow::Result;
use harness::replay::ReplayReader;
use scenarios::pusht::frame_score::FrameScorer;
use scenarios::pusht::{Pose2, PushTConfig};
use serde::Serialize;
use world_model::data::EpisodeData;
use world_model::eval::Video;

/// What scoring a dataset's frames needs: its scenario and the goal at every step.
pub struct Scoring {
    cfg: PushTConfig,
    /// Goal pose at each step.
    goals: Vec<Pose2>,
    size: usize,
}

/// One model's open-loop scores over the whole-episode videos.
#[derive(Clone, Debug, Serialize)]
pub struct ScoreRow {
    /// Model name ("persistence" for the last context frame repeated).
    pub name: String,
    /// Mean score of the real frames.
    pub real_mean: f64,
    /// Mean score of the generated frames.
    pub imagined_mean: f64,
    /// Mean |imagined − real| per video.
    pub mean_abs_error: f64,
    /// Videos scored.
    pub videos: usize,
}

impl Scoring {
    /// Reads the goal columns and the scenario of the dataset at `path`; `None` (with
    /// the reason) for a dataset without them (not collected by evalharness).
    ///
    /// # Errors
    /// An unreadable state array.
    pub fn load(path: &std::path::Path, size: usize) -> Result<Result<Self, String>> {
        let r = ReplayReader::open(path)?;
        let Ok(cfg) =
            serde_json::from_value::<PushTConfig>(r.attrs["evalharness"]["scenario_config"].clone())
        else {
            return Ok(Err("the dataset records no evalharness scenario".into()));
        };
        let dim = r.state.row_len();
        if dim < 8 {
            return Ok(Err(format!("data/state has {dim} columns, not the 8 with the goal")));
        }
        let state = r.state.read_f64()?;
        let goals = state.chunks(dim).map(|s| Pose2::new(s[5], s[6], s[7])).collect();
        Ok(Ok(Self { cfg, goals, size }))
    }

    fn score(&self, scorer: &FrameScorer, frames: &[Vec<u8>]) -> f64 {
        let thr = self.cfg.task.success_coverage;
        frames.iter().map(|f| (scorer.coverage(f) / thr).clamp(0.0, 1.0)).fold(0.0, f64::max)
    }

    /// (real, imagined) scores of `videos`, each read against its episode's goal;
    /// `imagined` scores a video's stand-in for its real frames.
    fn pairs(&self, videos: &[Video], imagined: impl Fn(&FrameScorer, &Video) -> f64) -> Vec<(f64, f64)> {
        videos
            .iter()
            .map(|v| {
                let scorer = FrameScorer::new(&self.cfg, &self.goals[v.start], self.size);
                (self.score(&scorer, &v.real), imagined(&scorer, v))
            })
            .collect()
    }

    /// Scores `videos` (each from its episode's goal) against their real frames.
    pub fn row(&self, name: &str, videos: &[Video]) -> ScoreRow {
        summarise(name, &self.pairs(videos, |sc, v| self.score(sc, &v.generated)))
    }

    /// The "nothing moves" reference: the last context frame (`start + k − 1`) for the
    /// whole video.
    pub fn persistence(&self, data: &EpisodeData, videos: &[Video], k: usize) -> ScoreRow {
        let last = |v: &Video| vec![data.frame(v.start + k - 1).to_vec()];
        summarise("persistence", &self.pairs(videos, |sc, v| self.score(sc, &last(v))))
    }
}

/// Means over (real, imagined) score pairs.
fn summarise(name: &str, pairs: &[(f64, f64)]) -> ScoreRow {
    let n = pairs.len().max(1) as f64;
    ScoreRow {
        name: name.to_string(),
        real_mean: pairs.iter().map(|p| p.0).sum::<f64>() / n,
        imagined_mean: pairs.iter().map(|p| p.1).sum::<f64>() / n,
        mean_abs_error: pairs.iter().map(|p| (p.1 - p.0).abs()).sum::<f64>() / n,
        videos: pairs.len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_averages_scores_and_absolute_errors() {
        // Pairs (real, imagined): (0.2, 0.5) and (0.6, 0.4): real mean 0.4, imagined
        // mean 0.45, |errors| 0.3 and 0.2, mean 0.25.
        let row = summarise("m", &[(0.2, 0.5), (0.6, 0.4)]);
        assert!((row.real_mean - 0.4).abs() < 1e-12);
        assert!((row.imagined_mean - 0.45).abs() < 1e-12);
        assert!((row.mean_abs_error - 0.25).abs() < 1e-12);
        assert_eq!(row.videos, 2);
    }
}
