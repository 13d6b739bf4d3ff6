//! The judge interface: scores an episode that happened only in the world model.
//!
//! The imagined branch has no simulator state, only decoded frames, so its score
//! comes from a [`Judge`] that reads a frame and estimates the raw score the task
//! would give the scene it shows (see [`ScoreKind`](crate::task::ScoreKind)).
//! Push-T's colour-mask coverage scorer is one judge; a learned classifier or
//! regressor trained on simulator frames labelled with the exact score is another,
//! and needs no hand-written pixel rules. Every run also judges the simulator
//! branch's real frames, and reports the judge's mean absolute error against the
//! exact score there (`frame_scorer_mean_abs_error`).
//!
//! A judge may also check that a frame still shows the scene ([`SceneCheck`]): a
//! long autoregressive rollout can lose it, and a judge then still reads a score
//! from a blob.

/// Health checks of one frame: is the scene still there? (Not a score.)
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneCheck {
    /// The manipulated object's pixels as a fraction of its true area (about 1 on
    /// real frames; Push-T: the T block).
    pub block_area: f64,
    /// Fraction of the goal still shown (1 on real frames).
    pub goal_kept: f64,
    /// Fraction of the agent (Push-T: its disk) still shown.
    pub agent_kept: f64,
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
    fn score(&self, frame: &[u8]) -> f64 {
        self.scorer.score(frame)
    }
    fn scene(&self, frame: &[u8]) -> Option<SceneCheck> {
        self.checks.as_ref().and_then(|c| c.scene(frame))
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

    struct Checks;
    impl Judge for Checks {
        fn score(&self, _: &[u8]) -> f64 {
            -1.0
        }
        fn scene(&self, _: &[u8]) -> Option<SceneCheck> {
            Some(SceneCheck { block_area: 1.0, goal_kept: 0.5, agent_kept: 0.25 })
        }
    }

    #[test]
    fn a_replaced_judge_scores_with_one_and_checks_with_the_other() {
        let j = Replaced { scorer: std::sync::Arc::new(Mean), checks: Some(Box::new(Checks)) };
        // Mean of 0 and 255 over 255: 0.5.
        assert_eq!(j.score(&[0, 255]), 0.5);
        assert_eq!(j.scene(&[0, 255]).map(|c| c.goal_kept), Some(0.5));
        assert_eq!(Mean.scene(&[0]), None);
        // Without the task's judge there are no scene checks.
        let j = Replaced { scorer: std::sync::Arc::new(Mean), checks: None };
        assert_eq!((j.score(&[255]), j.scene(&[255])), (1.0, None));
    }
}
