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
