//! A task's scripted behaviours and its dataset layout, behind one interface
//! ([`Scripted`], reached through [`crate::task::Task::scripted`]).
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
use crate::task::TaskError;

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
    /// The state before each action, as [`crate::task::Env::state`] gives it.
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
