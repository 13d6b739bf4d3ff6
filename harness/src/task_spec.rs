//! What a task declares and hands over, apart from the [`Task`](crate::task::Task) and
//! [`Env`](crate::task::Env) traits that use it: its action and observation specs, the robot-state
//! keys, how it is scored, what an episode shows ([`Seen`], [`NativeFrame`]), its errors,
//! the world model's view of it and the cost a planner minimises. The judges, policies and
//! scripted behaviours that a task returns read these types, so they sit below `task`.
//! `harness::task` re-exports them.

/// How a task reads an action vector.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionKind {
    /// Absolute targets (Push-T: the agent's target position in world units).
    Absolute,
    /// Changes relative to the current state (robomimic: end-effector deltas in
    /// [-1, 1], scaled by the controller, plus a gripper command).
    Delta,
}

/// A task's action space.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ActionSpec {
    /// Entries per action.
    pub dim: usize,
    /// Lower bound of each entry.
    pub low: Vec<f32>,
    /// Upper bound of each entry.
    pub high: Vec<f32>,
    /// Absolute or delta.
    pub kind: ActionKind,
}

/// Where a planar pushing task's state rows hold the poses its frames show ([`Task::pose_labels`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PoseColumns {
    /// The pushed object's x, y, θ.
    pub object: [usize; 3],
    /// The goal's x, y, θ.
    pub goal: [usize; 3],
}

impl PoseColumns {
    /// The state columns a row must have for both poses.
    pub fn columns_needed(&self) -> usize {
        self.object.iter().chain(&self.goal).max().map_or(0, |m| m + 1)
    }
}

/// What a policy observes in a task.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ObservationSpec {
    /// Side of the square RGB frames, in pixels.
    pub image_size: usize,
    /// The camera views, in the order their frames are given (one today).
    pub cameras: Vec<String>,
    /// Names of the proprioceptive vector's entries, in order.
    pub proprio: Vec<String>,
    /// The robot's measured state that policies trained elsewhere read (robomimic's
    /// `robot0_eef_pos`, …), key by key in [`Seen::robot`]'s order; empty where the task
    /// gives none (Push-T).
    pub robot: Vec<StateKey>,
}

/// One named entry of [`Seen::robot`]: `width` consecutive values.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StateKey {
    /// The key, as the codebases that record it name it (`robot0_eef_pos`).
    pub name: String,
    /// Values.
    pub width: usize,
}

impl StateKey {
    /// A key of `width` values.
    pub fn new(name: &str, width: usize) -> Self {
        Self { name: name.to_string(), width }
    }
}

/// A robot-state key a policy reads that the scenario does not give.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error(
    "reads `{key}`, which the scenario does not give (it gives: {})",
    if gives.is_empty() { "nothing".to_string() } else { gives.join(", ") }
)]
pub struct MissingStateKey {
    /// The key asked for.
    pub key: String,
    /// The keys the scenario gives, in its order.
    pub gives: Vec<String>,
}

/// Where each of `wanted`'s keys lies in a robot-state vector laid out as `keys`: the
/// `(offset, width)` of each, in `wanted`'s order.
///
/// # Errors
/// [`MissingStateKey`]: the first wanted key the layout lacks, with the keys it has.
pub fn robot_slices(keys: &[StateKey], wanted: &[String]) -> Result<Vec<(usize, usize)>, MissingStateKey> {
    let mut at = std::collections::BTreeMap::new();
    let mut offset = 0;
    for k in keys {
        at.insert(k.name.as_str(), (offset, k.width));
        offset += k.width;
    }
    wanted
        .iter()
        .map(|w| {
            at.get(w.as_str()).copied().ok_or_else(|| MissingStateKey {
                key: w.clone(),
                gives: keys.iter().map(|k| k.name.clone()).collect(),
            })
        })
        .collect()
}

/// How an episode is scored. Every step yields a raw value (the exact one from
/// the simulator's state, or a judge's estimate from a frame); the episode's score
/// is the best per-step reward, and it succeeds when the raw value passes the
/// threshold.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum ScoreKind {
    /// Push-T: the raw value is the goal coverage c; the reward is
    /// clip(c / `success_at`, 0, 1) and success is c > `success_at`.
    Coverage {
        /// Coverage above which the episode succeeds (0.95).
        success_at: f64,
    },
    /// robomimic: the raw value is 1 on success and 0 otherwise (a learned judge may
    /// give a probability); reward and success are raw > 0.5.
    Success,
}

impl ScoreKind {
    /// The reward of one step's raw value, in [0, 1].
    pub fn reward(&self, raw: f64) -> f64 {
        match *self {
            Self::Coverage { success_at } => (raw / success_at).clamp(0.0, 1.0),
            Self::Success => {
                if raw > 0.5 {
                    1.0
                } else {
                    0.0
                }
            }
        }
    }

    /// The episode score in words, as summaries state it.
    pub fn describe(&self) -> String {
        match *self {
            Self::Coverage { success_at } => {
                format!("max over the episode of clip(coverage / {success_at}, 0, 1)")
            }
            Self::Success => "1 if the task succeeded at some step, else 0".to_string(),
        }
    }

    /// The raw value an episode must exceed to succeed.
    pub fn threshold(&self) -> f64 {
        match *self {
            Self::Coverage { success_at } => success_at,
            Self::Success => 0.5,
        }
    }
}

/// One observation: a frame and the proprioceptive vector seen with it.
#[derive(Clone, Debug, PartialEq)]
pub struct Seen {
    /// `size x size x 3` bytes, HWC RGB.
    pub frame: Vec<u8>,
    /// The entries [`ObservationSpec::proprio`] names (Push-T: the agent's position).
    pub proprio: Vec<f32>,
    /// The keys [`ObservationSpec::robot`] names, in order: measured in the simulator,
    /// estimated from the commands in imagination ([`Imagination::robot`]).
    pub robot: Vec<f32>,
    /// A generated frame's values before rounding to bytes (HWC, [0, 1], unclamped), where
    /// the run feeds a world model's frames to policies as floats (`rank --float-frames`).
    pub exact: Option<Vec<f32>>,
    /// The camera's frame at the side it was rendered at, where the scene renders at another
    /// side than the observation's and resizes (Lift and Can with `[visual] render_size`):
    /// the bytes `frame` was made from. A policy trained at that side reads it instead of
    /// resizing `frame` back. Only a simulator has one.
    pub native: Option<NativeFrame>,
}

/// A frame at the side its camera rendered it at ([`Seen::native`]).
#[derive(Clone, Debug, PartialEq)]
pub struct NativeFrame {
    /// Side in pixels.
    pub side: usize,
    /// `side x side x 3` bytes, HWC RGB.
    pub bytes: Vec<u8>,
}

/// A `scripted` policy folder for a task that has none ([`Task::scripted_policy`]).
#[derive(Debug, thiserror::Error)]
#[error("{}: task {task} has no scripted policies", dir.display())]
pub struct NoScriptedPolicies {
    /// The policy folder.
    pub dir: std::path::PathBuf,
    /// The task.
    pub task: String,
}

/// An error of a task's simulator (a diverging step, a bad action, an impossible
/// reset), naming the task, seed and step where the task knows them.
#[derive(Debug, thiserror::Error)]
#[error(transparent)]
pub struct TaskError(pub Box<dyn std::error::Error + Send + Sync>);

impl TaskError {
    /// Wraps a task's own error type.
    pub fn new(e: impl std::error::Error + Send + Sync + 'static) -> Self {
        Self(Box::new(e))
    }
}

/// What the world model is fed of an episode's frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelView {
    /// The policy's observation itself.
    Observation,
    /// A view without the episode's goal (Push-T's goal-free world models): the
    /// goal is drawn back onto every decoded frame before anyone sees it.
    GoalFree,
}

/// What a planner minimises on a frame of the policy's view, lower being better
/// (Push-T: the mean distance of the block's pixels from the goal T).
pub trait PlanCost: Send + Sync {
    /// The frame's cost; `None` where the frame shows too little to judge (no
    /// block, a wrong size).
    fn cost(&self, frame: &[u8]) -> Option<f64>;
}
