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

use scenarios::pusht::frame_score::FrameScorer;
use scenarios::pusht::goal_free::DatasetScene;
use serde::Serialize;
use world_model::data::EpisodeData;
use world_model::eval::Video;

/// What scoring a dataset's frames needs: its scenario and the goal at every step.
pub struct Scoring<'s> {
    scene: &'s DatasetScene,
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
    /// Pearson r between the videos' real and imagined scores (does the model tell a
    /// good episode from a bad one?); `None` below 3 videos or without spread.
    pub pearson: Option<f64>,
    /// Videos scored.
    pub videos: usize,
    /// Mean coverage of the real and the generated frame at a few frame indices after
    /// the context: where, along the rollout, the imagined block leaves the real one.
    pub coverage_curve: Vec<CurvePoint>,
}

/// Mean coverage at one frame index over the videos that long.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct CurvePoint {
    /// Frame index after the context (0 = the first generated frame).
    pub frame: usize,
    /// Mean coverage of the real frames at that index.
    pub real: f64,
    /// Mean coverage of the stand-in frames at that index.
    pub imagined: f64,
    /// Videos with a frame at that index.
    pub videos: usize,
}

/// The frame indices of [`ScoreRow::coverage_curve`].
const CURVE_AT: [usize; 8] = [0, 8, 16, 32, 64, 128, 192, 256];

/// One video's scores and per-frame coverages (real, stand-in).
struct Scored {
    real: f64,
    imagined: f64,
    coverage: Vec<(f64, f64)>,
}

impl<'s> Scoring<'s> {
    /// Scores frames of `size` pixels against the goals of the dataset's `scene`.
    pub fn new(scene: &'s DatasetScene, size: usize) -> Self {
        Self { scene, size }
    }

    /// The scorer of the video starting at dataset step `start`.
    pub fn scorer(&self, start: usize) -> FrameScorer {
        FrameScorer::new(&self.scene.cfg, &self.scene.goal(start), self.size)
    }

    /// Scores `videos`, each read against its episode's goal; `stand_in(v, j)` is the
    /// frame standing in for real frame `j` of video `v`.
    fn scored<'a>(
        &self,
        videos: &'a [Video],
        stand_in: impl Fn(&'a Video, usize) -> &'a [u8],
    ) -> Vec<Scored> {
        let thr = self.scene.cfg.task.success_coverage;
        let score =
            |covs: &mut dyn Iterator<Item = f64>| covs.map(|c| (c / thr).clamp(0.0, 1.0)).fold(0.0, f64::max);
        videos
            .iter()
            .map(|v| {
                let scorer = self.scorer(v.start);
                let coverage: Vec<(f64, f64)> = (0..v.real.len())
                    .map(|j| (scorer.coverage(&v.real[j]), scorer.coverage(stand_in(v, j))))
                    .collect();
                let real = score(&mut coverage.iter().map(|c| c.0));
                let imagined = score(&mut coverage.iter().map(|c| c.1));
                Scored { real, imagined, coverage }
            })
            .collect()
    }

    /// Scores `videos` (each from its episode's goal) against their real frames.
    pub fn row(&self, name: &str, videos: &[Video]) -> ScoreRow {
        summarise(name, &self.scored(videos, |v, j| &v.generated[j]))
    }

    /// The "nothing moves" reference: the last context frame (`start + k − 1`) for the
    /// whole video.
    pub fn persistence(&self, data: &EpisodeData, videos: &[Video], k: usize) -> ScoreRow {
        summarise("persistence", &self.scored(videos, |v, _| data.frame(v.start + k - 1)))
    }
}

/// Means over the videos' scores, their correlation, and the coverage curve.
fn summarise(name: &str, videos: &[Scored]) -> ScoreRow {
    let n = videos.len().max(1) as f64;
    let (real, imagined): (Vec<f64>, Vec<f64>) = videos.iter().map(|v| (v.real, v.imagined)).unzip();
    let coverage_curve = CURVE_AT
        .iter()
        .filter_map(|&frame| {
            let at: Vec<(f64, f64)> = videos.iter().filter_map(|v| v.coverage.get(frame).copied()).collect();
            let m = at.len() as f64;
            (!at.is_empty()).then(|| CurvePoint {
                frame,
                real: at.iter().map(|c| c.0).sum::<f64>() / m,
                imagined: at.iter().map(|c| c.1).sum::<f64>() / m,
                videos: at.len(),
            })
        })
        .collect();
    ScoreRow {
        name: name.to_string(),
        real_mean: real.iter().sum::<f64>() / n,
        imagined_mean: imagined.iter().sum::<f64>() / n,
        mean_abs_error: real.iter().zip(&imagined).map(|(r, i)| (i - r).abs()).sum::<f64>() / n,
        pearson: if videos.len() >= 3 { harness::metrics::pearson(&real, &imagined) } else { None },
        videos: videos.len(),
        coverage_curve,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn video(real: f64, imagined: f64, coverage: &[(f64, f64)]) -> Scored {
        Scored { real, imagined, coverage: coverage.to_vec() }
    }

    #[test]
    fn summary_averages_scores_and_absolute_errors() {
        // Scores (real, imagined): (0.2, 0.5) and (0.6, 0.4): real mean 0.4, imagined
        // mean 0.45, |errors| 0.3 and 0.2, mean 0.25. Two videos: no Pearson r.
        let row = summarise("m", &[video(0.2, 0.5, &[]), video(0.6, 0.4, &[])]);
        assert!((row.real_mean - 0.4).abs() < 1e-12);
        assert!((row.imagined_mean - 0.45).abs() < 1e-12);
        assert!((row.mean_abs_error - 0.25).abs() < 1e-12);
        assert_eq!(row.videos, 2);
        assert_eq!(row.pearson, None);
    }

    #[test]
    fn pearson_and_coverage_curve() {
        // Imagined = 0.5·real + 0.1 exactly: r = 1. Real (0, 0.2, 0.4) against
        // reversed imagined (0.3, 0.2, 0.1): r = −1.
        let same: Vec<Scored> = [0.0, 0.2, 0.4].iter().map(|&r| video(r, 0.5 * r + 0.1, &[])).collect();
        assert!((summarise("m", &same).pearson.unwrap() - 1.0).abs() < 1e-12);
        let rev: Vec<Scored> =
            [(0.0, 0.3), (0.2, 0.2), (0.4, 0.1)].iter().map(|&(r, i)| video(r, i, &[])).collect();
        assert!((summarise("m", &rev).pearson.unwrap() + 1.0).abs() < 1e-12);
        // Curve: video A has 9 frames, B 1. Frame 0: real (0.1 + 0.3)/2 = 0.2, imagined
        // (0.5 + 0.7)/2 = 0.6 over 2 videos; frame 8: A's alone (0.4, 0.9); no frame 16.
        let mut a = vec![(0.0, 0.0); 9];
        a[0] = (0.1, 0.5);
        a[8] = (0.4, 0.9);
        let row = summarise("m", &[video(0.4, 0.9, &a), video(0.3, 0.7, &[(0.3, 0.7)])]);
        let close = |p: &CurvePoint, f: usize, r: f64, i: f64, n: usize| {
            p.frame == f && (p.real - r).abs() < 1e-12 && (p.imagined - i).abs() < 1e-12 && p.videos == n
        };
        assert_eq!(row.coverage_curve.len(), 2, "{:?}", row.coverage_curve);
        assert!(close(&row.coverage_curve[0], 0, 0.2, 0.6, 2), "{:?}", row.coverage_curve);
        assert!(close(&row.coverage_curve[1], 8, 0.4, 0.9, 1), "{:?}", row.coverage_curve);
    }
}
