//! A task's scripted behaviours and its dataset layout, behind one interface
//! ([`Scripted`], reached through [`crate::task_spec::Task::scripted`]).
//!
//! Why here: `simulate` and `collect` run any task's scripted behaviours (an expert and
//! the ways weak policies fail), and every command that writes a dataset of a task's
//! episodes (`collect`, `collect --policy`, `simulate --replay-imagined --record`) writes
//! the task's own layout. With this interface those commands know no task: a task
//! declares its behaviours, runs them on worker threads in seed order, and turns an
//! episode into dataset arrays, all in its own folder of `scenarios`.

use crate::replay::EpisodeArrays;
use crate::replay::ReplaySpec;
use crate::replay::attrs::DatasetAttrs;
use crate::task_spec::TaskError;

/// How scripted episodes run (the data commands' flags, checked by their parser).
#[derive(Clone, Copy, Debug)]
pub struct Settings {
    /// Gaussian noise on the behaviours' actions (the task's action units).
    pub noise: f64,
    /// Control steps by which the behaviours' actions lag.
    pub lag: usize,
    /// Control steps per episode.
    pub max_steps: usize,
    /// End an episode at its first success (tasks where [`Scripted::early_stop_optional`]).
    pub stop_at_success: bool,
    /// Worker threads.
    pub jobs: usize,
}

/// Frames an episode is asked to keep (`simulate`'s GIF, `collect`'s observations).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameRequest {
    /// Side in pixels.
    pub size: usize,
    /// The reference renderer's frame beside the task's own (frames twice as wide), for
    /// tasks with two renderers ([`Scripted::second_renderer`]).
    pub beside_reference: bool,
}

/// One scripted episode, as the data commands write it.
#[derive(Clone, Debug)]
pub struct ScriptedEpisode {
    /// Its seed.
    pub seed: u64,
    /// How a dataset names its behaviour (a perturbed expert is not an expert:
    /// `expert+noise80+lag2` on Push-T).
    pub behaviour: String,
    /// Its arrays in the task's dataset layout ([`Scripted::layout`]).
    pub arrays: EpisodeArrays,
    /// The exact score of the episode (Push-T: the best coverage reward; tasks scored by
    /// success: 1 or 0).
    pub score: f64,
    /// Whether it succeeded.
    pub success: bool,
    /// Control steps taken.
    pub steps: usize,
    /// Control steps until its first success (none for a failure).
    pub steps_to_success: Option<usize>,
    /// The frames asked for ([`FrameRequest`]), one per observation; empty if none.
    pub frames: Vec<Vec<u8>>,
    /// One JSON line per control step for `simulate`'s `episodes.jsonl`, in the task's
    /// own columns.
    pub step_lines: Vec<String>,
    /// The drawn initial state as one JSON line (`simulate`'s `initial_states.jsonl`),
    /// for tasks whose initial state another simulator can start from.
    pub initial_state: Option<String>,
}

/// A task's dataset layout: the arrays and its own attributes.
#[derive(Clone, Debug)]
pub struct Layout {
    /// The arrays' shapes and extras.
    pub spec: ReplaySpec,
    /// The task's attributes (scenario, its config, the meaning of each array); the
    /// commands add the seeds, the source and the episodes.
    pub header: DatasetAttrs,
}

/// A recorded episode of the task (a policy's closed loop in the simulator), to be
/// written in the task's layout: the frame and state before each action, the action,
/// and the raw score after it.
#[derive(Clone, Copy, Debug)]
pub struct Recorded<'a> {
    /// The episode's seed.
    pub seed: u64,
    /// At least one frame per action, `size × size × 3` bytes.
    pub frames: &'a [Vec<u8>],
    /// The state before each action, as [`crate::task_spec::Env::state`] gives it.
    pub states: &'a [Vec<f64>],
    /// Each action.
    pub actions: &'a [Vec<f32>],
    /// The raw score after each action.
    pub raw: &'a [f64],
    /// The goal pose, for tasks that have one.
    pub goal: Option<[f64; 3]>,
    /// The episode's exact score.
    pub score: f64,
    /// Whether it succeeded.
    pub success: bool,
}

/// A recorded episode whose arrays do not fit its task's dataset layout.
#[derive(Debug, thiserror::Error)]
#[error("recorded episode seed {seed}: {message}")]
pub struct RecordedMismatch {
    /// The episode's seed.
    pub seed: u64,
    /// What does not fit, naming the step.
    pub message: String,
}

impl Recorded<'_> {
    /// Checks that there is a frame (at least), a state and a raw score for every action.
    ///
    /// # Errors
    /// The counts, when they do not match.
    pub fn check_counts(&self) -> Result<(), RecordedMismatch> {
        let n = self.actions.len();
        if self.frames.len() < n || self.states.len() != n || self.raw.len() != n {
            let (f, s, r) = (self.frames.len(), self.states.len(), self.raw.len());
            let message = format!("{f} frames, {s} states, {r} scores for {n} actions");
            return Err(RecordedMismatch { seed: self.seed, message });
        }
        Ok(())
    }

    /// The arrays of a layout that stores each step's frame (`size`² RGB), state (`columns`
    /// entries) and action (`actions` entries) as recorded, and one extra per step: 1 where
    /// the raw score after the action is above `threshold` (success), else 0.
    ///
    /// # Errors
    /// Fewer frames than actions, states or scores of another count, or a step whose frame,
    /// state or action has another size, naming the step.
    pub fn success_arrays(
        &self,
        (size, columns, actions): (usize, usize, usize),
        threshold: f64,
    ) -> Result<EpisodeArrays, RecordedMismatch> {
        self.check_counts()?;
        let bad = |message: String| RecordedMismatch { seed: self.seed, message };
        let mut arrays = EpisodeArrays::default();
        for (j, ((f, s), a)) in self.frames.iter().zip(self.states).zip(self.actions).enumerate() {
            if f.len() != size * size * 3 || s.len() != columns || a.len() != actions {
                return Err(bad(format!(
                    "step {j}: frame of {} bytes, state of {} entries or action of {}, expected {}, {columns} and {actions}",
                    f.len(),
                    s.len(),
                    a.len(),
                    size * size * 3
                )));
            }
            arrays.img.extend_from_slice(f);
            arrays.state.extend(s.iter().map(|&v| v as f32));
            arrays.action.extend_from_slice(a);
        }
        arrays.extras.push(self.raw.iter().map(|&r| if r > threshold { 1.0 } else { 0.0 }).collect());
        Ok(arrays)
    }
}

/// Receives each episode of [`Scripted::run`] with its index in the work list.
pub type EpisodeSink<'a> = dyn FnMut(usize, ScriptedEpisode) -> Result<(), TaskError> + 'a;

/// Which frames [`Scripted::run`] keeps of the episode at an index of the work list.
pub type FrameChoice<'a> = dyn Fn(usize) -> Option<FrameRequest> + Sync + 'a;

/// A task's scripted behaviours and dataset layout.
pub trait Scripted: Send + Sync {
    /// The behaviours by name, the expert first.
    fn behaviours(&self) -> Vec<&'static str>;
    /// `collect`'s mix when `--mix` is not given (`name=weight,…`).
    fn default_mix(&self) -> String;
    /// Whether an episode may run on past its first success (`--no-early-stop`): tasks
    /// scored by success may; Push-T's episodes end at success as gym-pusht's do.
    fn early_stop_optional(&self) -> bool;
    /// Whether the task draws its frames with a renderer of its own beside MuJoCo's, so
    /// that `simulate --renderer mujoco` can show both.
    fn second_renderer(&self) -> bool {
        false
    }
    /// The task's configuration as `config.json` records it.
    fn config_json(&self) -> serde_json::Value;
    /// The state columns' names.
    fn state_columns(&self) -> Vec<String>;
    /// The task's dataset layout for frames of its observation size.
    fn layout(&self) -> Layout;
    /// A recorded episode's arrays in [`Scripted::layout`].
    ///
    /// # Errors
    /// Arrays of another shape than the layout's, naming the step.
    fn recorded_arrays(&self, episode: &Recorded<'_>) -> Result<EpisodeArrays, TaskError>;
    /// Runs one episode per `(seed, behaviour index)` of `work` on `settings.jobs`
    /// threads and hands each to `done` in the order of `work`; `frames(i)` says which
    /// frames episode `i` keeps. Every random stream of an episode derives from its seed,
    /// so any number of threads gives the same episodes.
    ///
    /// # Errors
    /// Threads that cannot be started, the first episode that fails (naming the task, its
    /// seed and behaviour), or what `done` returns.
    fn run(
        &self,
        work: &[(u64, usize)],
        settings: &Settings,
        frames: &FrameChoice<'_>,
        done: &mut EpisodeSink<'_>,
    ) -> Result<(), TaskError>;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn recorded<'a>(
        frames: &'a [Vec<u8>],
        states: &'a [Vec<f64>],
        actions: &'a [Vec<f32>],
        raw: &'a [f64],
    ) -> Recorded<'a> {
        Recorded { seed: 7, frames, states, actions, raw, goal: None, score: 0.75, success: true }
    }

    #[test]
    fn success_arrays_mark_success_after_each_action_above_the_threshold() {
        // raw after each of 4 actions: 0, 0.25, 0.5, 0.75; above 0.4: the last two.
        let (frames, states, actions) = (vec![vec![1; 12]; 5], vec![vec![0.5; 3]; 4], vec![vec![0.1; 7]; 4]);
        let raw: Vec<f64> = (0..4).map(|j| f64::from(j) / 4.0).collect();
        let a = recorded(&frames, &states, &actions, &raw).success_arrays((2, 3, 7), 0.4).unwrap();
        assert_eq!(a.extras, vec![vec![0.0, 0.0, 1.0, 1.0]]);
        // 4 frames of 2·2·3 bytes (the final frame is not stored), 4·3 states, 4·7 actions.
        assert_eq!((a.img.len(), a.state.len(), a.action.len()), (48, 12, 28));
    }

    #[test]
    fn success_arrays_name_the_step_of_a_wrong_shape() {
        let (frames, mut states, mut actions) =
            (vec![vec![1; 12]; 4], vec![vec![0.5; 3]; 3], vec![vec![0.1; 7]; 3]);
        let raw = vec![0.0; 3];
        actions[1] = vec![0.0; 6];
        let err = recorded(&frames, &states, &actions, &raw)
            .success_arrays((2, 3, 7), 0.5)
            .unwrap_err()
            .to_string();
        assert!(err.contains("seed 7") && err.contains("step 1") && err.contains("action of 6"), "{err}");
        actions[1] = vec![0.0; 7];
        states.pop();
        let err = recorded(&frames, &states, &actions, &raw)
            .success_arrays((2, 3, 7), 0.5)
            .unwrap_err()
            .to_string();
        assert!(err.contains("2 states") && err.contains("3 actions"), "{err}");
    }
}
