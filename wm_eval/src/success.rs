//! `wm eval --judge`: the open-loop success check, for tasks scored by success alone
//! (Lift, Can).
//!
//! Why: `rank` imagines weak policies succeeding (BENCHMARKS.md, the Lift and Can
//! headlines). Two things can cause that: the closed loop (the policy, acting on
//! imagined frames, does better than it does in MuJoCo) or the dynamics (the model
//! draws a grasp that the actions never make). Here each whole episode's recorded
//! actions are replayed from its 4 real frames, with no policy in the loop, and the
//! learned judge reads the generated and the real frames the way `rank` reads an
//! imagined episode: the first frame and the last 2 of every 8 (the shipped
//! policies' chunk and horizon), success once the estimate holds above the
//! threshold for the judge's k judged frames in a row. Episodes are grouped by the
//! dataset's `behaviour`; on `collect --policy` rollouts that is the checkpoint, so
//! the groups are an open-loop version of `rank`'s per-policy success rates, set
//! against the exact success the dataset records.

use std::collections::BTreeMap;
use std::path::Path;

use harness::replay::ReplayReader;
use judges::folder::FrameJudge;
use judges::metrics::Reading;
use judges::read::held_success;
use serde::Serialize;
use world_model::data::EpisodeData;
use world_model::eval::Video;

use crate::WmEvalError;

/// What `eval.json`'s `open_loop_success` says it measured.
pub const SUCCESS_NOTE: &str = "whole-episode videos: the recorded actions replayed from 4 real frames (no \
    policy in the loop); the judge reads the first frame and the last 2 of every 8 as rank does, success once \
    its estimate holds above the threshold for its persist_frames judged frames in a row; \"exact\" is the \
    dataset's data/success at any step of the episode";

/// One episode as the check reads it.
#[derive(Clone, Debug, PartialEq)]
struct Outcome {
    /// The dataset's `behaviour` of the episode (a checkpoint's name for rollouts).
    group: String,
    /// The dataset's exact success at any step (none without `data/success`).
    exact: Option<bool>,
    /// The judge's reading of the real frames.
    real: bool,
    /// The judge's reading of the generated frames.
    imagined: bool,
}

/// Rates over a set of episodes.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Rates {
    /// The dataset's `behaviour` ("all" for the whole set).
    pub group: String,
    /// Episodes.
    pub episodes: usize,
    /// Exact success rate (`data/success`), when the dataset has it.
    pub exact: Option<f64>,
    /// Success rate the judge reads from the real frames.
    pub judged_real: f64,
    /// Success rate the judge reads from the generated frames.
    pub imagined: f64,
    /// Episodes that fail (exactly, else as the judge reads the real frames) and are
    /// imagined succeeding.
    pub false_successes: usize,
    /// Of `false_successes`, the exact failures whose real frames the judge reads as
    /// succeeding too: the judge's misreading, which no world model could avoid. The
    /// rest are the model's. Always 0 without exact labels.
    pub false_successes_judge_misreads: usize,
    /// Episodes that succeed and are imagined failing.
    pub missed_successes: usize,
}

/// One model's open-loop success check.
#[derive(Clone, Debug, Serialize)]
pub struct SuccessRow {
    /// Model name.
    pub name: String,
    /// Every episode together.
    pub all: Rates,
    /// One row per behaviour, in name order.
    pub groups: Vec<Rates>,
    /// Pearson r between the groups' true (exact, else judged-real) and imagined rates:
    /// `rank`'s headline without the closed loop; `None` below 3 groups or without spread.
    pub pearson: Option<f64>,
}

/// The judge, and what the dataset says of each episode.
pub struct SuccessCheck {
    judge: FrameJudge,
    reading: Reading,
    /// Per episode: its behaviour and exact success.
    episodes: Vec<(String, Option<bool>)>,
}

impl SuccessCheck {
    /// Loads the judge at `dir` for the dataset at `path` (already read as `data`).
    ///
    /// # Errors
    /// An unreadable judge, one that reads frames of another size, or an unreadable
    /// `data/success` array.
    pub fn load(dir: &Path, path: &Path, data: &EpisodeData) -> Result<Self, WmEvalError> {
        let judge = runner::inputs::read_judge_folder(dir, &burn::tensor::Device::flex())?;
        if judge.image_size() != data.size {
            return Err(WmEvalError::JudgeSize {
                judge: dir.to_path_buf(),
                data: path.to_path_buf(),
                judged: judge.image_size(),
                frames: data.size,
            });
        }
        let r = ReplayReader::open(path)?;
        let labels = r.extra("success")?;
        let attrs = harness::replay::origin::episodes_in(path, &r.attrs)?;
        let episodes = data
            .episodes
            .iter()
            .enumerate()
            .map(|(i, range)| {
                let group = attrs.get(i).and_then(|a| a.behaviour.clone()).unwrap_or_else(|| "all".into());
                let exact = labels.as_ref().map(|l| l[range.clone()].iter().any(|&v| v > 0.5));
                (group, exact)
            })
            .collect();
        let reading = Reading::rank(judge.file.persist_frames);
        Ok(Self { judge, reading, episodes })
    }

    /// Whether the judge reads a success in `frames` (episode times 0, 1, …).
    fn reads_success(&self, frames: &[&[u8]]) -> bool {
        let picked: Vec<&[u8]> =
            frames.iter().enumerate().filter(|(t, _)| self.reading.judged(*t)).map(|(_, f)| *f).collect();
        held_success(self.judge.score_frames(&picked), self.reading.persist, self.judge.file.threshold)
    }

    /// Reads `videos` (whole episodes; `episode_of(start)` names each one's episode) for
    /// the model `name`; `k` context frames precede each video's frames.
    pub fn row(
        &self,
        name: &str,
        data: &EpisodeData,
        videos: &[Video],
        k: usize,
        episode_of: impl Fn(usize) -> usize,
    ) -> SuccessRow {
        let outcomes: Vec<Outcome> = videos
            .iter()
            .map(|v| {
                let context: Vec<&[u8]> = (v.start..v.start + k).map(|i| data.frame(i)).collect();
                let real: Vec<&[u8]> =
                    context.iter().copied().chain(v.real.iter().map(Vec::as_slice)).collect();
                let generated: Vec<&[u8]> =
                    context.iter().copied().chain(v.generated.iter().map(Vec::as_slice)).collect();
                let (group, exact) = self.episodes[episode_of(v.start)].clone();
                let (real, imagined) = (self.reads_success(&real), self.reads_success(&generated));
                Outcome { group, exact, real, imagined }
            })
            .collect();
        summarise(name, &outcomes)
    }
}

/// The rates of `outcomes`, labelled `group`.
fn rates(group: &str, outcomes: &[&Outcome]) -> Rates {
    let n = outcomes.len().max(1) as f64;
    let rate = |f: &dyn Fn(&Outcome) -> bool| outcomes.iter().filter(|o| f(o)).count() as f64 / n;
    let truth = |o: &Outcome| o.exact.unwrap_or(o.real);
    Rates {
        group: group.to_string(),
        episodes: outcomes.len(),
        exact: outcomes.iter().all(|o| o.exact.is_some()).then(|| rate(&|o| o.exact == Some(true))),
        judged_real: rate(&|o| o.real),
        imagined: rate(&|o| o.imagined),
        false_successes: outcomes.iter().filter(|o| !truth(o) && o.imagined).count(),
        false_successes_judge_misreads: outcomes
            .iter()
            .filter(|o| o.exact == Some(false) && o.real && o.imagined)
            .count(),
        missed_successes: outcomes.iter().filter(|o| truth(o) && !o.imagined).count(),
    }
}

/// Rates over every episode and per group, and the groups' correlation.
fn summarise(name: &str, outcomes: &[Outcome]) -> SuccessRow {
    let mut by_group: BTreeMap<&str, Vec<&Outcome>> = BTreeMap::new();
    for o in outcomes {
        by_group.entry(&o.group).or_default().push(o);
    }
    let groups: Vec<Rates> = by_group.iter().map(|(g, os)| rates(g, os)).collect();
    let truth: Vec<f64> = groups.iter().map(|g| g.exact.unwrap_or(g.judged_real)).collect();
    let imagined: Vec<f64> = groups.iter().map(|g| g.imagined).collect();
    SuccessRow {
        name: name.to_string(),
        all: rates("all", &outcomes.iter().collect::<Vec<_>>()),
        pearson: if groups.len() >= 3 { harness::metrics::pearson(&truth, &imagined) } else { None },
        groups,
    }
}

/// `row` as a few lines of text.
pub fn lines(row: &SuccessRow) -> Vec<String> {
    let line = |r: &Rates| {
        let exact = r.exact.map_or_else(|| "n/a".to_string(), |e| format!("{e:.2}"));
        format!(
            "{:<16} {:>4} episodes  exact {exact}  judged real {:.2}  imagined {:.2}  false successes {} \
             (the judge misreads the real frames in {})  missed {}",
            r.group,
            r.episodes,
            r.judged_real,
            r.imagined,
            r.false_successes,
            r.false_successes_judge_misreads,
            r.missed_successes
        )
    };
    let r = row.pearson.map_or_else(|| "n/a".to_string(), |p| format!("{p:.3}"));
    let head = format!("{:<20} open-loop success, by behaviour (r over behaviours {r}):", row.name);
    std::iter::once(head)
        .chain(row.groups.iter().chain([&row.all]).map(|g| format!("{:<20} {}", "", line(g))))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn o(group: &str, exact: Option<bool>, real: bool, imagined: bool) -> Outcome {
        Outcome { group: group.into(), exact, real, imagined }
    }

    #[test]
    fn rates_count_false_and_missed_successes_against_the_exact_label() {
        // Group a: 4 episodes, exact (T, F, F, F); the judge reads the real frames
        // (T, T, F, F) and the imagined ones (T, T, T, F). Exact rate 1/4 = 0.25,
        // judged real 2/4 = 0.5, imagined 3/4 = 0.75; false successes: the 2 exact
        // failures imagined succeeding (episodes 2, 3), of which episode 2's real frames
        // the judge reads as succeeding too (1 misread); missed: none.
        let a = [o("a", Some(true), true, true), o("a", Some(false), true, true)];
        let a = [&a[..], &[o("a", Some(false), false, true), o("a", Some(false), false, false)]].concat();
        let row = summarise("m", &a);
        assert_eq!(row.groups.len(), 1);
        let g = &row.groups[0];
        assert_eq!((g.exact, g.judged_real, g.imagined), (Some(0.25), 0.5, 0.75));
        assert_eq!((g.false_successes, g.false_successes_judge_misreads, g.missed_successes), (2, 1, 0));
        assert_eq!(row.all, Rates { group: "all".into(), ..g.clone() });
        assert_eq!(row.pearson, None, "one group has no correlation");
    }

    #[test]
    fn without_exact_labels_the_judged_real_frames_are_the_truth() {
        // Real read (T, F), imagined (F, F): 1 missed success, no false one, no exact rate.
        let row = summarise("m", &[o("x", None, true, false), o("x", None, false, false)]);
        let g = &row.groups[0];
        assert_eq!((g.exact, g.judged_real, g.imagined), (None, 0.5, 0.0));
        assert_eq!((g.false_successes, g.missed_successes), (0, 1));
        // A judged-real success imagined succeeding is no false success, and without
        // exact labels nothing is counted as the judge's misreading.
        let row = summarise("m", &[o("x", None, true, true), o("x", None, false, true)]);
        let g = &row.groups[0];
        assert_eq!((g.false_successes, g.false_successes_judge_misreads), (1, 0));
    }

    #[test]
    fn groups_are_sorted_by_name_and_correlated() {
        // Groups b, a, c of one episode each, exact (F, T, T) in the order a, b, c =
        // (1, 0, 1); imagined (a 1, b 0, c 0). Pearson of (1, 0, 1) and (1, 0, 0):
        // means 2/3 and 1/3; deviations (1/3, −2/3, 1/3) and (2/3, −1/3, −1/3);
        // covariance sum 2/9 + 2/9 − 1/9 = 1/3; norms √(6/9) and √(6/9), product 2/3;
        // r = (1/3) / (2/3) = 0.5.
        let os = [
            o("b", Some(false), false, false),
            o("a", Some(true), true, true),
            o("c", Some(true), true, false),
        ];
        let row = summarise("m", &os);
        let names: Vec<&str> = row.groups.iter().map(|g| g.group.as_str()).collect();
        assert_eq!(names, ["a", "b", "c"]);
        assert!((row.pearson.unwrap() - 0.5).abs() < 1e-12, "{:?}", row.pearson);
        assert_eq!((row.all.false_successes, row.all.missed_successes), (0, 1));
    }
}
