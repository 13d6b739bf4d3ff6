//! The judge interface: scores an episode that happened only in the world model.
//!
//! The imagined branch has no simulator state, only decoded frames, so its score
//! comes from a [`Judge`] that reads a frame and estimates the raw score the task
//! would give the scene it shows (see [`ScoreKind`](crate::task_spec::ScoreKind)).
//! Push-T's colour-mask coverage scorer is one judge; a learned classifier or
//! regressor trained on simulator frames labelled with the exact score is another,
//! and needs no hand-written pixel rules. Every run also judges the simulator
//! branch's real frames, and reports the judge's mean absolute error against the
//! exact score there (`frame_scorer_mean_abs_error`).
//!
//! A judge may also check that a frame still shows the scene ([`SceneCheck`]): a
//! long autoregressive rollout can lose it, and a judge then still reads a score
//! from a blob.
//!
//! A judge may ask for persistence ([`Judge::persist`]): a success must show on k
//! judged frames in a row before the episode counts it. Its score at a frame is
//! the lowest of the last k judged frames, so one frame a judge misreads (a
//! flicker of the world model, a cube the fingers hide) cannot end an imagined
//! episode as a success. With k = 1 (the default) every frame counts alone.

/// Health checks of one frame: is the scene still there? (Not a score.) Named by the
/// task's judge, in its own order, each about 1 on real frames and lower where an imagined
/// rollout lost part of the scene (Push-T's: `block_area`, the T block's pixels as a fraction
/// of its true area; `goal_kept`, the fraction of the goal still shown; `agent_kept`, the
/// fraction of the agent's disk). Episode rows keep them by name
/// ([`EpisodeRow::scene`](crate::results::EpisodeRow::scene)).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SceneCheck(pub Vec<(&'static str, f64)>);

impl SceneCheck {
    /// The check named `name`, if the judge made it.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.0.iter().find(|(n, _)| *n == name).map(|&(_, v)| v)
    }
}

/// Scores imagined frames of one episode.
pub trait Judge: Send + Sync {
    /// The raw score the frame shows: an estimate of what the task's exact score
    /// would be for that scene.
    fn score(&self, frame: &[u8]) -> f64;
    /// Scene checks of the frame, for judges that make them.
    fn scene(&self, frame: &[u8]) -> Option<SceneCheck> {
        let _ = frame;
        None
    }
    /// Judged frames in a row the score must hold before it counts (at least 1).
    fn persist(&self) -> usize {
        1
    }
    /// For a judge that reads the manipulated object's pose rather than a score (GPC's
    /// reward predictors): the pose the frame shows, in the task's units (Push-T: x, y, θ).
    /// Its score then comes from the episode's own judge ([`Judge::score_pose`]), through
    /// [`Replaced`]. `None`: the judge scores frames itself.
    fn pose(&self, frame: &[u8]) -> Option<Vec<f64>> {
        let _ = frame;
        None
    }
    /// The raw score of the episode's scene with the manipulated object at `pose` (Push-T:
    /// the exact goal coverage of a block there), for a task judge that can compute it.
    fn score_pose(&self, pose: &[f64]) -> Option<f64> {
        let _ = pose;
        None
    }
}

/// The episode's score so far under persistence `k`: each judged frame's raw value
/// becomes the lowest of the last `k` (none until `k` frames were judged).
#[derive(Clone, Debug, Default)]
pub struct Sustained {
    k: usize,
    last: std::collections::VecDeque<f64>,
}

impl Sustained {
    /// Persistence `k` (0 is read as 1).
    pub fn new(k: usize) -> Self {
        Self { k: k.max(1), last: std::collections::VecDeque::new() }
    }

    /// Adds one judged frame's raw value; returns the value held over the last `k`
    /// frames, or `None` while fewer than `k` were judged.
    pub fn push(&mut self, raw: f64) -> Option<f64> {
        self.last.push_back(raw);
        while self.last.len() > self.k {
            self.last.pop_front();
        }
        (self.last.len() == self.k).then(|| self.last.iter().copied().fold(f64::INFINITY, f64::min))
    }
}

/// A judge whose scores come from one judge (e.g. a learned one, shared by every
/// episode) and whose scene checks come from another (the task's own, which knows
/// the episode's goal, where the task has one): what `rank --judge` puts in place
/// of the task's judge.
pub struct Replaced {
    /// Gives the scores.
    pub scorer: std::sync::Arc<dyn Judge>,
    /// Gives the scene checks.
    pub checks: Option<Box<dyn Judge>>,
}

impl Judge for Replaced {
    /// The scorer's score; for a scorer that reads poses, the episode judge's score of that
    /// pose (NaN where the task cannot score a pose: the engine then stops, naming the judge).
    fn score(&self, frame: &[u8]) -> f64 {
        match self.scorer.pose(frame) {
            Some(p) => self.checks.as_ref().and_then(|c| c.score_pose(&p)).unwrap_or(f64::NAN),
            None => self.scorer.score(frame),
        }
    }
    fn scene(&self, frame: &[u8]) -> Option<SceneCheck> {
        self.checks.as_ref().and_then(|c| c.scene(frame))
    }
    fn persist(&self) -> usize {
        self.scorer.persist()
    }
}

/// A planner's cost from a judge: `1 − score` of the frame (lower is better, as every
/// [`crate::task_spec::PlanCost`]), `None` where the judge's score is not a number in [0, 1]
/// (a pose it cannot place, say). What `plan --judge` ranks proposals by, as GPC-RANK
/// ranks them by its reward predictors.
pub struct JudgedCost(pub Box<dyn Judge>);

impl crate::task_spec::PlanCost for JudgedCost {
    fn cost(&self, frame: &[u8]) -> Option<f64> {
        let s = self.0.score(frame);
        (0.0..=1.0).contains(&s).then_some(1.0 - s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Mean;
    impl Judge for Mean {
        fn score(&self, frame: &[u8]) -> f64 {
            frame.iter().map(|&b| f64::from(b)).sum::<f64>() / frame.len() as f64 / 255.0
        }
    }

    #[test]
    fn a_judged_cost_is_one_minus_the_score_and_none_off_the_unit_interval() {
        use crate::task_spec::PlanCost;
        let c = JudgedCost(Box::new(Mean));
        // Mean of [255, 0] over 255 = 0.5; cost 1 - 0.5.
        assert_eq!(c.cost(&[255, 0]), Some(0.5));
        assert_eq!(c.cost(&[255, 255]), Some(0.0));
        let nan = JudgedCost(Box::new(Replaced { scorer: std::sync::Arc::new(Poser), checks: None }));
        assert_eq!(nan.cost(&[1]), None);
    }

    /// Reads a pose, and cannot score one.
    struct Poser;
    impl Judge for Poser {
        fn score(&self, _: &[u8]) -> f64 {
            0.0
        }
        fn pose(&self, _: &[u8]) -> Option<Vec<f64>> {
            Some(vec![1.0, 2.0, 3.0])
        }
    }

    struct Checks;
    impl Judge for Checks {
        fn score(&self, _: &[u8]) -> f64 {
            -1.0
        }
        fn scene(&self, _: &[u8]) -> Option<SceneCheck> {
            Some(SceneCheck(vec![("block_area", 1.0), ("goal_kept", 0.5), ("agent_kept", 0.25)]))
        }
    }

    #[test]
    fn a_replaced_judge_scores_with_one_and_checks_with_the_other() {
        let j = Replaced { scorer: std::sync::Arc::new(Mean), checks: Some(Box::new(Checks)) };
        // Mean of 0 and 255 over 255: 0.5.
        assert_eq!(j.score(&[0, 255]), 0.5);
        assert_eq!(j.scene(&[0, 255]).and_then(|c| c.get("goal_kept")), Some(0.5));
        assert_eq!(Mean.scene(&[0]), None);
        // Without the task's judge there are no scene checks.
        let j = Replaced { scorer: std::sync::Arc::new(Mean), checks: None };
        assert_eq!((j.score(&[255]), j.scene(&[255])), (1.0, None));
        // Persistence comes from the scorer.
        assert_eq!(j.persist(), 1);
        struct Three;
        impl Judge for Three {
            fn score(&self, _: &[u8]) -> f64 {
                0.0
            }
            fn persist(&self) -> usize {
                3
            }
        }
        let j = Replaced { scorer: std::sync::Arc::new(Three), checks: Some(Box::new(Checks)) };
        assert_eq!((j.persist(), j.score(&[0])), (3, 0.0));
    }

    #[test]
    fn a_sustained_score_is_the_lowest_of_the_last_k_frames() {
        // k = 2 over 0.9, 0.2, 0.8, 0.7: none yet, min(0.9, 0.2), min(0.2, 0.8), min(0.8, 0.7).
        let mut s = Sustained::new(2);
        let got: Vec<Option<f64>> = [0.9, 0.2, 0.8, 0.7].into_iter().map(|r| s.push(r)).collect();
        assert_eq!(got, vec![None, Some(0.2), Some(0.2), Some(0.7)]);
        // k = 0 is read as 1: every frame counts alone.
        let mut s = Sustained::new(0);
        assert_eq!((s.push(0.4), s.push(0.1)), (Some(0.4), Some(0.1)));
    }
}
