//! Reading whole recorded episodes with a judge, the way `rank` reads an imagined
//! one, so that a judge's rule can be chosen on real episodes whose exact success
//! is known.
//!
//! `rank` judges only the frames the policy sees: the first, then the last `seen`
//! of every executed chunk of `chunk` steps ([`Reading::judged`]). An episode
//! succeeds once the judge's score holds above the threshold for `persist` judged
//! frames in a row ([`harness::judge::Sustained`], the engine's own rule). The
//! exact truth is the dataset's label at any step, judged or not, as the
//! simulator branch scores it.

use std::path::Path;

use harness::judge::Sustained;
use harness::replay::ReplayReader;

use crate::error::JudgeError;
use crate::folder::{FrameJudge, Label};
use crate::metrics::{EpisodeReading, JudgeMetrics, Reading, metrics};

/// Frames and labels of a dataset.
pub struct JudgeData {
    /// `n x s x s x 3` bytes.
    pub frames: Vec<u8>,
    /// `n` labels.
    pub labels: Vec<f32>,
    /// Frame side.
    pub size: usize,
    /// Step ranges of each episode.
    pub episodes: Vec<std::ops::Range<usize>>,
}

impl JudgeData {
    /// Loads the first `limit` episodes (all if `None`) of a dataset with its
    /// `data/<label>` array.
    ///
    /// # Errors
    /// [`JudgeError`] naming the dataset for an unreadable layout, a missing
    /// label array, non-finite labels or no episodes.
    pub fn load(path: &Path, label: Label, limit: Option<usize>) -> Result<Self, JudgeError> {
        let err = |what: String| JudgeError::Dataset { path: path.into(), what };
        let replay = |source| JudgeError::Replay { path: path.into(), source };
        let r = ReplayReader::open(path).map_err(replay)?;
        let Some(all) = r.extra(label.array()).map_err(replay)? else {
            return Err(err(format!("no data/{} array to learn from", label.array())));
        };
        if let Some(t) = all.iter().position(|v| !v.is_finite()) {
            return Err(err(format!("data/{} is not finite at step {t}", label.array())));
        }
        let n = limit.unwrap_or(usize::MAX).min(r.episodes());
        if n == 0 {
            return Err(err("no episodes".into()));
        }
        let episodes: Vec<_> = (0..n).map(|i| r.episode_range(i)).collect();
        let end = episodes.last().map_or(0, |e| e.end);
        let frames = r.img.read_rows(0, end).map_err(replay)?;
        let labels = all[..end].iter().map(|&v| v as f32).collect();
        Ok(Self { frames, labels, size: r.img.shape()[1], episodes })
    }

    /// Frame `i`.
    pub fn frame(&self, i: usize) -> &[u8] {
        let n = self.size * self.size * 3;
        &self.frames[i * n..(i + 1) * n]
    }

    /// Steps of the training and held-out episodes (every 10th episode is held out).
    pub fn split(&self) -> (Vec<usize>, Vec<usize>) {
        let mut sets = (Vec::new(), Vec::new());
        for (e, r) in self.episodes.iter().enumerate() {
            if held_out(e) { sets.1.extend(r.clone()) } else { sets.0.extend(r.clone()) }
        }
        sets
    }

    /// Step ranges of the held-out episodes.
    pub fn held_out_episodes(&self) -> Vec<std::ops::Range<usize>> {
        self.episodes.iter().enumerate().filter(|&(e, _)| held_out(e)).map(|(_, r)| r.clone()).collect()
    }
}

/// Whether episode `e` is held out: every 10th.
fn held_out(e: usize) -> bool {
    e % 10 == 9
}

/// One episode's judged frames: the judge's estimates and the exact labels there,
/// and whether the episode truly succeeds at any step.
#[derive(Clone, Debug, PartialEq)]
pub struct JudgedEpisode {
    /// The judge's estimate of each judged frame, in time order.
    pub estimates: Vec<f64>,
    /// The exact label of each judged frame.
    pub labels: Vec<f64>,
    /// The exact label is above the threshold at some step.
    pub success: bool,
}

/// Scores the judged frames of `episodes` (step ranges of `data`).
pub fn judge_episodes(
    judge: &FrameJudge,
    data: &JudgeData,
    episodes: &[std::ops::Range<usize>],
    reading: &Reading,
    threshold: f64,
) -> Vec<JudgedEpisode> {
    episodes
        .iter()
        .map(|r| {
            let steps: Vec<usize> = r.clone().filter(|&i| reading.judged(i - r.start)).collect();
            let mut estimates = Vec::with_capacity(steps.len());
            for part in steps.chunks(64) {
                let frames: Vec<&[u8]> = part.iter().map(|&i| data.frame(i)).collect();
                estimates.extend(judge.score_frames(&frames));
            }
            JudgedEpisode {
                estimates,
                labels: steps.iter().map(|&i| f64::from(data.labels[i])).collect(),
                success: r.clone().any(|i| f64::from(data.labels[i]) > threshold),
            }
        })
        .collect()
}

/// Whether an episode whose judged frames have `estimates` (in time order) succeeds:
/// once the estimate holds above `threshold` for `persist` judged frames in a row.
pub fn held_success(estimates: impl IntoIterator<Item = f64>, persist: usize, threshold: f64) -> bool {
    let mut held = Sustained::new(persist);
    estimates.into_iter().any(|v| held.push(v).is_some_and(|h| h > threshold))
}

/// Reads judged episodes with persistence `persist` ([`held_success`]).
pub fn read_judged(episodes: &[JudgedEpisode], persist: usize, threshold: f64) -> EpisodeReading {
    EpisodeReading::of(
        episodes.iter().map(|e| (held_success(e.estimates.iter().copied(), persist, threshold), e.success)),
    )
}

/// Frame metrics over every judged frame of `episodes`.
pub fn judged_frame_metrics(episodes: &[JudgedEpisode], threshold: f64) -> JudgeMetrics {
    let est: Vec<f64> = episodes.iter().flat_map(|e| e.estimates.iter().copied()).collect();
    let labels: Vec<f64> = episodes.iter().flat_map(|e| e.labels.iter().copied()).collect();
    metrics(&est, &labels, threshold)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rank_judges_the_first_frame_and_each_chunks_last_two() {
        // chunk 8, seen 2: t % 8 in {0, 7}, so 0, 7, 8, 15, 16 of 0..17.
        let r = Reading::rank(1);
        let t: Vec<usize> = (0..17).filter(|&t| r.judged(t)).collect();
        assert_eq!(t, vec![0, 7, 8, 15, 16]);
        // seen 1: only the chunk boundaries; seen >= chunk: every frame.
        let one = Reading { chunk: 4, seen: 1, persist: 1 };
        assert_eq!((0..9).filter(|&t| one.judged(t)).collect::<Vec<_>>(), vec![0, 4, 8]);
        let all = Reading { chunk: 2, seen: 2, persist: 1 };
        assert!((0..5).all(|t| all.judged(t)));
        assert_eq!(Reading::rank(0).persist, 1);
    }

    #[test]
    fn persistence_turns_a_flicker_into_a_failure() {
        let ep = |estimates: Vec<f64>, success| JudgedEpisode {
            labels: vec![0.0; estimates.len()],
            estimates,
            success,
        };
        // A failure with one frame at 0.9, a success held for 3 frames, a success the
        // judge sees only once.
        let eps = vec![
            ep(vec![0.1, 0.9, 0.1, 0.2], false),
            ep(vec![0.1, 0.8, 0.9, 0.7], true),
            ep(vec![0.1, 0.2, 0.6, 0.1], true),
        ];
        // k = 1: all three called successes: 2 agree, 1 false success, none missed.
        let r = read_judged(&eps, 1, 0.5);
        assert_eq!((r.agree, r.false_successes, r.missed_successes), (2, 1, 0));
        // k = 2: the flicker and the single frame drop out: 2 agree, 0 false, 1 missed.
        let r = read_judged(&eps, 2, 0.5);
        assert_eq!((r.agree, r.false_successes, r.missed_successes), (2, 0, 1));
        // k = 4: nothing holds for 4 frames: the failure agrees, both successes missed.
        let r = read_judged(&eps, 4, 0.5);
        assert_eq!((r.agree, r.missed_successes), (1, 2));
    }
}
