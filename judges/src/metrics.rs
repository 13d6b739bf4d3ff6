//! What a judge is scored by, shared by the judge itself ([`crate::folder`]), the reading of
//! recorded episodes ([`crate::read`]) and training ([`crate::train`]): which
//! frames of an episode `rank` judges ([`Reading`]), a judge's metrics on real frames and
//! episodes, and those metrics computed from estimates and labels. Its own module so that
//! those three depend on it and not on each other.

use serde::{Deserialize, Serialize};

/// Actions the shipped policies execute per decision: `rank` judges at this period.
pub const RANK_CHUNK: usize = 8;
/// Frames the shipped policies see at the end of each chunk (their observation horizon).
pub const RANK_SEEN: usize = 2;

/// Which frames of an episode are judged, and how many in a row must show success.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Reading {
    /// Actions executed per policy decision (the shipped policies: 8).
    pub chunk: usize,
    /// Frames the policy sees at the end of each chunk (its observation horizon, 2).
    pub seen: usize,
    /// Judged frames in a row that must show success.
    pub persist: usize,
}

impl Reading {
    /// `rank`'s reading with the shipped policies' chunk (8) and horizon (2).
    pub fn rank(persist: usize) -> Self {
        Self { chunk: RANK_CHUNK, seen: RANK_SEEN, persist: persist.max(1) }
    }

    /// Whether the frame at time `t` (the observation before action `t`) is judged:
    /// the first, and the observations after each chunk's last `seen` actions,
    /// i.e. `t % chunk` in {0} ∪ [chunk − seen + 1, chunk). Every frame when
    /// `chunk` is 0 or `seen` ≥ `chunk`.
    pub fn judged(&self, t: usize) -> bool {
        if self.chunk == 0 || self.seen >= self.chunk {
            return true;
        }
        let r = t % self.chunk;
        r == 0 || r > self.chunk - self.seen
    }
}

/// How well a judge reads a set of real frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JudgeMetrics {
    /// Frames judged.
    pub frames: usize,
    /// Frames whose label is above the threshold.
    pub positives: usize,
    /// Mean |estimate − label|.
    pub mean_abs_error: f64,
    /// Fraction of frames on the label's side of the threshold.
    pub accuracy: f64,
    /// Of the frames above the threshold, the fraction the judge puts above it.
    pub recall: Option<f64>,
    /// Of the frames the judge puts above the threshold, the fraction truly above it.
    pub precision: Option<f64>,
    /// Whole held-out episodes read as `rank` reads an imagined one (absent in judges
    /// written before it was measured).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub episodes: Option<EpisodeReading>,
}

/// How a judge reads whole episodes, by its reading ([`Reading`]: the
/// frames `rank` judges, k in a row) and by the exact label (at any step).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EpisodeReading {
    /// The frames judged and the persistence (absent in judges that read every frame
    /// alone, written before the rule existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reading: Option<Reading>,
    /// Episodes judged.
    pub episodes: usize,
    /// Episodes that truly succeed.
    pub successes: usize,
    /// Episodes the judge reads right (success or not).
    pub agree: usize,
    /// Failed episodes the judge calls successes.
    pub false_successes: usize,
    /// Successful episodes the judge calls failures.
    pub missed_successes: usize,
}

impl EpisodeReading {
    /// Counts `(judged success, true success)` pairs, one per episode.
    pub fn of(pairs: impl IntoIterator<Item = (bool, bool)>) -> Self {
        let mut r = Self::default();
        for (said, truth) in pairs {
            r.episodes += 1;
            r.successes += usize::from(truth);
            r.agree += usize::from(said == truth);
            r.false_successes += usize::from(said && !truth);
            r.missed_successes += usize::from(!said && truth);
        }
        r
    }
}

/// [`JudgeMetrics`] of estimates against labels.
pub fn metrics(est: &[f64], labels: &[f64], threshold: f64) -> JudgeMetrics {
    let n = est.len().min(labels.len());
    let (mut abs, mut right, mut tp, mut pos, mut said) = (0.0, 0usize, 0usize, 0usize, 0usize);
    for (&e, &y) in est.iter().zip(labels) {
        abs += (e - y).abs();
        let (pe, py) = (e > threshold, y > threshold);
        right += usize::from(pe == py);
        tp += usize::from(pe && py);
        pos += usize::from(py);
        said += usize::from(pe);
    }
    let frac = |a: usize, b: usize| (b > 0).then(|| a as f64 / b as f64);
    JudgeMetrics {
        frames: n,
        positives: pos,
        mean_abs_error: if n > 0 { abs / n as f64 } else { 0.0 },
        accuracy: frac(right, n).unwrap_or(0.0),
        recall: frac(tp, pos),
        precision: frac(tp, said),
        episodes: None,
    }
}
