//! The task interface: what a reference simulator gives the paired engine.
//!
//! A [`Task`] (Push-T, robomimic Lift, Can, ...) declares its action space, its
//! observation and how it is scored, and per episode seed makes an [`Env`]: a
//! simulator reset to that seed's initial state (a pure function of the seed)
//! that steps one action at a time, renders what the policy sees and scores itself
//! exactly from privileged state.
//!
//! The imagined branch of an episode happens only in the world model. All it may
//! know of the episode is taken once, at reset, from the [`Env`]: the first
//! observation, an [`Imagination`] (what the world model is fed and what is drawn
//! back onto its frames, and the proprioception the policy reads, integrated from
//! its own commands) and a [`Judge`](crate::judge::Judge) of imagined frames. It
//! never reads the simulator's state after that.
//!
//! Everything here is plain data (u8 frames, f32/f64 vectors): no MuJoCo, no burn.

use std::path::Path;

use crate::judge::Judge;
use crate::policy::Policy;
pub use crate::task_spec::{
    ActionKind, ActionSpec, MissingStateKey, ModelView, NativeFrame, NoScriptedPolicies, ObservationSpec,
    PlanCost, PoseColumns, ScoreKind, Seen, StateKey, TaskError, robot_slices,
};

/// The world-model adaptor of one episode, made at reset from what the episode
/// shows publicly (Push-T: its first frame and its goal). The imagined branch
/// knows nothing else of the episode.
pub trait Imagination: Send + Sync {
    /// The frame the world model starts from, in its view.
    fn first_frame(&self) -> &[u8];
    /// Turns a decoded frame of the model's view into the policy's observation
    /// (draws back the goal for [`ModelView::GoalFree`]; a no-op otherwise).
    fn to_observation(&self, frame: &mut [u8]);
    /// Takes one commanded action (every executed one, in order).
    fn advance(&mut self, action: &[f32]);
    /// The proprioception the policy reads with the newest imagined frame, from the
    /// commands alone (Push-T: the last commanded target standing in for the agent's
    /// position, as DriftWorld evaluates).
    fn proprio(&self) -> Vec<f32>;
    /// The estimate of [`ObservationSpec::robot`] with the newest imagined frame, from what
    /// the episode showed at reset and the commands since (none by default).
    fn robot(&self) -> Vec<f32> {
        Vec::new()
    }
}

/// One episode of a task's reference simulator.
pub trait Env: Send {
    /// The episode seed it was reset to.
    fn seed(&self) -> u64;
    /// What the policy sees now.
    fn observe(&self) -> Seen;
    /// Executes one action for one control step and returns the exact raw score
    /// after it ([`ScoreKind`]).
    ///
    /// # Errors
    /// A non-finite action or a diverging simulation, naming seed and step.
    fn step(&mut self, action: &[f32]) -> Result<f64, TaskError>;
    /// The exact raw score of the current state.
    fn score(&self) -> f64;
    /// The privileged state as datasets store it (Push-T: agent x, y, block x, y, θ).
    fn state(&self) -> Vec<f64>;
    /// The episode's fixed conditions, named, for both branches' rows (Push-T: `goal_x`,
    /// `goal_y`, `goal_theta`); read right after reset. None by default.
    fn conditions(&self) -> Vec<(&'static str, f64)> {
        Vec::new()
    }
    /// Named facts of the current state for the episode's MuJoCo row, read when it ends
    /// (Push-T: `final_block_x`, `final_block_y`, `final_block_theta`). None by default.
    fn final_state(&self) -> Vec<(&'static str, f64)> {
        Vec::new()
    }
    /// The goal pose (x, y, θ) a recorded episode keeps, where the task has one (Push-T's
    /// datasets store it). None by default.
    fn goal_pose(&self) -> Option<[f64; 3]> {
        None
    }
    /// The task's own judge of this episode's imagined frames, from its public
    /// conditions only (Push-T: the goal pose); `None` for a task without a
    /// hand-written one (robomimic's: a learned judge, `rank --judge`, scores them).
    fn judge(&self) -> Option<Box<dyn Judge>>;
    /// The world-model adaptor of this episode; call right after reset.
    fn imagination(&self, view: ModelView) -> Box<dyn Imagination>;
    /// The current frame in the world model's `view` (the planner's world model
    /// imagines from the last real frames). By default the adaptor's first frame at
    /// the current state.
    fn model_frame(&self, view: ModelView) -> Vec<u8> {
        self.imagination(view).first_frame().to_vec()
    }
    /// A copy of this episode at its current true state, on which `plan`'s simulator
    /// planner tries a proposal; `None` for a task that cannot copy one.
    fn fork(&self) -> Option<Box<dyn Env>> {
        None
    }
    /// The planners' cost of this episode's frames, from its public conditions (the
    /// goal); `None` for a task without one, which `plan` then refuses.
    fn plan_cost(&self) -> Option<Box<dyn PlanCost>> {
        None
    }
}

/// A task: the scenario, its declarations and its seeded episodes.
pub trait Task: Send + Sync {
    /// The scenario name (`pusht`, `lift`, ...).
    fn name(&self) -> &str;
    /// Its action space.
    fn action_spec(&self) -> ActionSpec;
    /// What its policies observe.
    fn observation_spec(&self) -> ObservationSpec;
    /// How its episodes are scored.
    fn score_kind(&self) -> ScoreKind;
    /// Control steps per episode unless asked otherwise.
    fn max_steps(&self) -> usize;
    /// Control steps per second.
    fn control_hz(&self) -> f64;
    /// Whether its episodes judge their own imagined frames ([`Env::judge`] is `Some`
    /// for every seed): a fact of the task, answered without a reset. A task without
    /// such a judge needs a learned one for `rank`'s world-model branch.
    fn judges_own_frames(&self) -> bool;
    /// The reference simulator's name, as `rank`'s table and reports say it ("MuJoCo", the
    /// default; Reach's is its own).
    fn simulator(&self) -> &'static str {
        "MuJoCo"
    }
    /// The task's parameters as loaded (its shipped ones or a scenario file's; for Lift and
    /// Can they include how frames are rendered), for a run's `config.json` and the
    /// fingerprint `--resume` and `merge` compare: a run is never continued on another scene,
    /// even one given by the same name. `None` for a task without recorded parameters.
    fn parameters(&self) -> Option<serde_json::Value> {
        None
    }
    /// A recorded configuration of this task (a dataset's `scenario_config`, a training-data
    /// recipe's) as [`Task::parameters`] writes one today, for comparing the two: a record
    /// written by an older evalharness may leave implicit what was then a default (Lift's and
    /// Can's rendering, before 2026-12-03). The record itself by default.
    fn recorded_parameters(&self, recorded: &serde_json::Value) -> serde_json::Value {
        recorded.clone()
    }
    /// The episode of `seed`, reset (a pure function of the seed).
    ///
    /// # Errors
    /// A seed whose reset fails (an impossible reset, a diverging first step).
    fn reset(&self, seed: u64) -> Result<Box<dyn Env>, TaskError>;
    /// The proprioception a policy read at each step of a recorded episode, given
    /// the episode's dataset rows (`states[t]` as [`Env::state`] gives it, `actions[t]`
    /// the action executed at step t): exactly what [`Env::observe`] gave at step t,
    /// so that policies train on what they will read. Push-T: the agent's position
    /// from the state; robomimic: the commanded pose integrated from the actions
    /// before step t.
    fn recorded_proprio(&self, states: &[Vec<f64>], actions: &[Vec<f32>]) -> Vec<Vec<f32>>;
    /// State columns (index into [`Env::state`], and name) that a frame shows and a
    /// policy must locate: privileged labels a policy's frame encoder may be
    /// pre-trained to regress, never a policy input. Empty when the task names none.
    fn frame_labels(&self) -> Vec<(usize, String)> {
        Vec::new()
    }
    /// The state columns of the poses a frame of a planar pushing task shows: the pushed
    /// object's and the goal's (x, y, θ), labels a policy's frame encoder may be pre-trained
    /// to regress through the square world's symmetries (Push-T). `None` by default.
    fn pose_labels(&self) -> Option<PoseColumns> {
        None
    }
    /// Frees what the calling thread holds for this task's episodes, before the thread
    /// ends: a thread that ran episodes calls it when it is done (robosuite's tasks drop
    /// the thread's GL context, which torn down at process exit instead corrupted the
    /// heap now and then). Nothing by default.
    fn release_thread(&self) {}
    /// A `scripted` policy checkpoint of this task (its expert acting from frames);
    /// tasks without scripted policies refuse.
    ///
    /// # Errors
    /// An unreadable or invalid `policy.json`, naming it; [`NoScriptedPolicies`] for a task
    /// without them.
    fn scripted_policy(&self, dir: &Path) -> Result<Box<dyn Policy>, TaskError> {
        Err(TaskError::new(NoScriptedPolicies { dir: dir.to_path_buf(), task: self.name().to_string() }))
    }
    /// The task's scripted behaviours and dataset layout (what `simulate` and `collect`
    /// run, and what every dataset of its episodes is written in); `None` for a task
    /// without them, which those commands then refuse.
    fn scripted(&self) -> Option<&dyn crate::scripted::Scripted> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rewards_and_thresholds_by_score_kind() {
        let cov = ScoreKind::Coverage { success_at: 0.95 };
        // 0.475 / 0.95 = 0.5; 0.99 / 0.95 > 1 clips to 1; negative clips to 0.
        assert_eq!(cov.reward(0.475), 0.5);
        assert_eq!(cov.reward(0.99), 1.0);
        assert_eq!(cov.reward(-0.1), 0.0);
        assert_eq!(cov.threshold(), 0.95);
        assert_eq!(cov.describe(), "max over the episode of clip(coverage / 0.95, 0, 1)");
        // Success: a probability of 0.7 is a success, 0.5 is not.
        assert_eq!(ScoreKind::Success.reward(0.7), 1.0);
        assert_eq!(ScoreKind::Success.reward(0.5), 0.0);
        assert_eq!(ScoreKind::Success.threshold(), 0.5);
    }

    #[test]
    fn pose_columns_need_a_row_past_their_last_column() {
        // Push-T's: object 2, 3, 4 and goal 5, 6, 7 need 8 columns; a GPC-like row of 5
        // (agent x, y, block x, y, θ) lacks the goal.
        let p = PoseColumns { object: [2, 3, 4], goal: [5, 6, 7] };
        assert_eq!(p.columns_needed(), 8);
        assert_eq!(PoseColumns { object: [0, 1, 2], goal: [9, 4, 3] }.columns_needed(), 10);
    }

    #[test]
    fn task_errors_keep_the_message_and_the_source() {
        let io = std::io::Error::other("step 3 diverged");
        let e = TaskError::new(io);
        assert_eq!(e.to_string(), "step 3 diverged");
        assert!(e.0.downcast_ref::<std::io::Error>().is_some());
    }

    #[test]
    fn robot_slices_find_each_wanted_key_or_name_the_missing_one() {
        let keys = [StateKey::new("eef_pos", 3), StateKey::new("eef_quat", 4), StateKey::new("qpos", 2)];
        // Offsets: eef_pos 0..3, eef_quat 3..7, qpos 7..9.
        let got = robot_slices(&keys, &["qpos".into(), "eef_pos".into()]).unwrap();
        assert_eq!(got, vec![(7, 2), (0, 3)]);
        let err = robot_slices(&keys, &["object".into()]).unwrap_err().to_string();
        assert!(err.contains("`object`") && err.contains("eef_pos, eef_quat, qpos"), "{err}");
        assert!(robot_slices(&[], &["x".into()]).unwrap_err().to_string().contains("gives: nothing"));
    }
}
