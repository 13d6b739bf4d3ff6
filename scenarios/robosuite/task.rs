//! robomimic Lift and Can as [`Task`]s: what the paired engine drives.
//!
//! - Actions: robomimic's 7-D vector, six end-effector deltas in [-1, 1] (scaled
//!   by OSC_POSE to 0.05 m and 0.5 rad) and the gripper command (−1 open, +1 closed).
//! - Observation: the 96x96 `agentview` frame and the **commanded pose**: the six
//!   deltas summed over the episode, scaled to metres and radians, and the last
//!   gripper command (7 entries; −1 before any command, the gripper starting open).
//!   The simulator branch computes it from the actions it executed, exactly as the
//!   imagined branch does from the same commands, so the policy reads the same
//!   quantity in both and the imagined branch never needs the simulator's state.
//!   It is not the arm's measured pose: a blocked or lagging arm differs from it,
//!   and the frame shows by how much.
//! - Score: success 0/1 exactly as robosuite checks it ([`ScoreKind::Success`]).
//! - Judge of imagined frames: none hand-written; a learned one (`train judge
//!   --label success`, `rank --judge DIR`) scores them.
//! - Imagination: the world model starts from the first frame as the policy sees it.
//!
//! One implementation serves both tasks, through [`ArmSim`]'s episode reset.

use std::cell::RefCell;

use harness::judge::Judge;
use harness::task::{
    ActionKind, ActionSpec, Env, Imagination, ModelView, NativeFrame, ObservationSpec, ScoreKind, Seen, Task,
    TaskError,
};

use super::arm_sim::{ArmScene, ArmSim, SceneEpisode};
use super::episode::ROBOT_COLUMNS;
use super::robot_state::{self, RobotEstimate};
use crate::error::ScenarioError;

/// Side of the agentview frames policies and world models read.
pub const IMAGE_SIZE: usize = 96;
/// OSC_POSE's scale of the position deltas (metres per unit action).
const POS_SCALE: f32 = super::osc::MAX_DPOS as f32;
/// OSC_POSE's scale of the rotation deltas (radians per unit action).
const ROT_SCALE: f32 = super::osc::MAX_DROT as f32;
/// Names of the proprioceptive entries.
pub const PROPRIO: [&str; 7] = ["cmd_x", "cmd_y", "cmd_z", "cmd_rx", "cmd_ry", "cmd_rz", "gripper_cmd"];

/// The commanded pose: the scaled deltas summed, and the last gripper command.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Commanded([f32; 7]);

impl Default for Commanded {
    fn default() -> Self {
        Self([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0])
    }
}

impl Commanded {
    /// Takes one executed action (entries clipped to [-1, 1], as the controller clips them).
    pub fn add(&mut self, action: &[f32]) {
        for (d, &a) in action.iter().take(6).enumerate() {
            let scale = if d < 3 { POS_SCALE } else { ROT_SCALE };
            self.0[d] += a.clamp(-1.0, 1.0) * scale;
        }
        if let Some(&g) = action.get(6) {
            self.0[6] = g.clamp(-1.0, 1.0);
        }
    }

    /// The proprioceptive vector ([`PROPRIO`]).
    pub fn vector(&self) -> Vec<f32> {
        self.0.to_vec()
    }
}

/// A robosuite task as a [`Task`].
pub struct RobosuiteTask<S: ArmScene> {
    sim: ArmSim<S>,
}

impl<S: ArmScene> RobosuiteTask<S> {
    /// Wraps a task's simulator.
    pub fn new(sim: ArmSim<S>) -> Self {
        Self { sim }
    }

    /// The task's simulator (its scripted behaviours, state columns and config).
    pub fn sim(&self) -> &ArmSim<S> {
        &self.sim
    }
}

impl<S: ArmScene> Task for RobosuiteTask<S> {
    fn name(&self) -> &str {
        self.sim.name()
    }

    fn parameters(&self) -> Option<serde_json::Value> {
        Some(self.sim.config_json())
    }

    fn recorded_parameters(&self, recorded: &serde_json::Value) -> serde_json::Value {
        crate::robosuite::visual::Visual::written_out(true, recorded)
    }

    fn action_spec(&self) -> ActionSpec {
        ActionSpec { dim: 7, low: vec![-1.0; 7], high: vec![1.0; 7], kind: ActionKind::Delta }
    }

    fn observation_spec(&self) -> ObservationSpec {
        ObservationSpec {
            image_size: IMAGE_SIZE,
            cameras: vec!["agentview".into()],
            proprio: PROPRIO.iter().map(|s| (*s).to_string()).collect(),
            robot: robot_state::keys(),
        }
    }

    fn judges_own_frames(&self) -> bool {
        // No hand-written rule reads success from a frame: `judge` is `None`.
        false
    }

    fn release_thread(&self) {
        crate::robosuite::renderer::release_renderer();
    }

    fn scripted(&self) -> Option<&dyn harness::scripted::Scripted> {
        Some(self)
    }

    fn score_kind(&self) -> ScoreKind {
        ScoreKind::Success
    }

    fn max_steps(&self) -> usize {
        self.sim.max_steps()
    }

    fn control_hz(&self) -> f64 {
        20.0
    }

    fn recorded_proprio(&self, _states: &[Vec<f64>], actions: &[Vec<f32>]) -> Vec<Vec<f32>> {
        // Step t reads the pose commanded by the actions before it, as `observe` does.
        let mut cmd = Commanded::default();
        actions
            .iter()
            .map(|a| {
                let seen = cmd.vector();
                cmd.add(a);
                seen
            })
            .collect()
    }

    fn frame_labels(&self) -> Vec<(usize, String)> {
        // The object's position (the state's first three columns), the end effector's
        // position and the two finger joints ([`ROBOT_COLUMNS`] after the object's seven).
        let robot = |name: &str| ROBOT_COLUMNS.iter().position(|c| *c == name).map(|i| 7 + i);
        let mut labels: Vec<(usize, String)> = ["object_x", "object_y", "object_z"]
            .iter()
            .enumerate()
            .map(|(i, n)| (i, (*n).to_string()))
            .collect();
        for name in ["eef_x", "eef_y", "eef_z", "finger_1", "finger_2"] {
            labels.extend(robot(name).map(|i| (i, name.to_string())));
        }
        labels
    }

    fn reset(&self, seed: u64) -> Result<Box<dyn Env>, TaskError> {
        let ep = self.sim.reset(seed).map_err(TaskError::new)?;
        Ok(Box::new(ArmEnv {
            seed,
            ep: RefCell::new(ep),
            frame: RefCell::new(None),
            cmd: Commanded::default(),
        }))
    }
}

/// One episode: the simulator, its frame (rendered when first observed after a
/// step) and the commanded pose.
struct ArmEnv<S: ArmScene> {
    seed: u64,
    ep: RefCell<SceneEpisode<S>>,
    frame: RefCell<Option<Rendered>>,
    cmd: Commanded,
}

/// A state's frame, and the camera's own where it renders at another side.
type Rendered = (Vec<u8>, Option<NativeFrame>);

impl<S: ArmScene> ArmEnv<S> {
    /// The current frame, rendered once per state.
    fn frame(&self) -> Result<Rendered, ScenarioError> {
        if let Some(f) = self.frame.borrow().as_ref() {
            return Ok(f.clone());
        }
        let mut ep = self.ep.borrow_mut();
        let arm = ep.arm_mut();
        let side = arm.render_size();
        let (frame, raw) = arm.render_native(IMAGE_SIZE)?;
        let f = (frame, raw.zip(side).map(|(bytes, side)| NativeFrame { side, bytes }));
        *self.frame.borrow_mut() = Some(f.clone());
        Ok(f)
    }
}

impl<S: ArmScene> Env for ArmEnv<S> {
    fn seed(&self) -> u64 {
        self.seed
    }

    fn observe(&self) -> Seen {
        // A renderer that cannot start fails on the first frame of every episode; an
        // empty frame then makes the policy refuse it with an error naming its size.
        let (frame, native) = self.frame().unwrap_or_else(|e| {
            tracing::error!(seed = self.seed, "rendering: {e}");
            (Vec::new(), None)
        });
        let robot = robot_state::measured(self.ep.borrow().arm());
        Seen { frame, proprio: self.cmd.vector(), robot, exact: None, native }
    }

    fn step(&mut self, action: &[f32]) -> Result<f64, TaskError> {
        let a: [f32; 7] = action.try_into().map_err(|_| {
            TaskError::new(ScenarioError::BadActionSize { seed: self.seed, expected: 7, got: action.len() })
        })?;
        self.ep.get_mut().arm_mut().step(&a.map(f64::from)).map_err(TaskError::new)?;
        *self.frame.get_mut() = None;
        self.cmd.add(&a);
        Ok(self.score())
    }

    fn score(&self) -> f64 {
        if self.ep.borrow().success() { 1.0 } else { 0.0 }
    }

    fn state(&self) -> Vec<f64> {
        self.ep.borrow().arm().state()
    }

    /// The object's final planar pose (the cube's or the can's centre, metres, and the yaw of its
    /// rotation about the world's z axis).
    fn final_state(&self) -> Vec<(&'static str, f64)> {
        let ep = self.ep.borrow();
        let ([x, y, _], [w, qx, qy, qz]) = (ep.arm().object_pos(), ep.arm().object_quat());
        let yaw = (2.0 * (w * qz + qx * qy)).atan2(1.0 - 2.0 * (qy * qy + qz * qz));
        vec![("final_object_x", x), ("final_object_y", y), ("final_object_yaw", yaw)]
    }

    fn judge(&self) -> Option<Box<dyn Judge>> {
        None
    }

    fn imagination(&self, _view: ModelView) -> Box<dyn Imagination> {
        // The scenes have no goal drawn in them, so both views are the observation.
        let first = self.frame().map(|(frame, _)| frame).unwrap_or_default();
        let robot = RobotEstimate::at_reset(self.ep.borrow().arm());
        Box::new(ArmImagination { first, cmd: self.cmd, robot })
    }
}

/// What the imagined branch knows of an episode: its first frame and robot state, then its
/// commands.
struct ArmImagination {
    first: Vec<u8>,
    cmd: Commanded,
    robot: RobotEstimate,
}

impl Imagination for ArmImagination {
    fn first_frame(&self) -> &[u8] {
        &self.first
    }

    fn to_observation(&self, _frame: &mut [u8]) {}

    fn advance(&mut self, action: &[f32]) {
        self.cmd.add(action);
        self.robot.advance(action);
    }

    fn proprio(&self) -> Vec<f32> {
        self.cmd.vector()
    }

    fn robot(&self) -> Vec<f32> {
        self.robot.vector()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::{CanConfig, CanSim};
    use crate::lift::{LiftConfig, LiftSim};

    fn lift() -> RobosuiteTask<crate::lift::sim::Lift> {
        RobosuiteTask::new(LiftSim::new(LiftConfig::default()).expect("robosuite assets (scripts/setup.sh)"))
    }

    #[test]
    fn lift_declares_robomimics_action_and_success_and_resets_by_seed() {
        let t = lift();
        assert_eq!((t.name(), t.action_spec().dim, t.action_spec().kind), ("lift", 7, ActionKind::Delta));
        assert_eq!(t.score_kind(), ScoreKind::Success);
        assert_eq!(t.observation_spec().proprio.len(), 7);
        let (a, b) = (t.reset(3).unwrap(), t.reset(3).unwrap());
        let seen = a.observe();
        assert_eq!(seen, b.observe());
        assert_eq!(seen.frame.len(), 96 * 96 * 3);
        // Nothing commanded yet: zero deltas and the gripper open.
        assert_eq!(seen.proprio, vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0]);
        assert_eq!((a.score(), a.state().len(), a.goal_pose()), (0.0, 23, None));
        assert!(a.judge().is_none(), "no hand-written judge of Lift frames");
        assert_ne!(t.reset(4).unwrap().state(), a.state());
        // The frames were rendered on this thread; releasing it drops its GL context.
        assert!(crate::robosuite::renderer::holds_renderer());
        t.release_thread();
        assert!(!crate::robosuite::renderer::holds_renderer());
    }

    #[test]
    fn both_branches_read_the_same_commanded_pose() {
        let t = lift();
        let mut env = t.reset(5).unwrap();
        let mut imagine = env.imagination(ModelView::Observation);
        let before = env.observe().frame;
        assert_eq!(imagine.first_frame(), &before[..]);
        // Clipped to [-1, 1], then 0.05 m or 0.5 rad per unit: x 1 → 0.05, y −0.5 → −0.025,
        // z 3 (clipped to 1) → 0.05, rz 0.2 → 0.1; gripper 1 (closed).
        let actions = [[1.0f32, -0.5, 3.0, 0.0, 0.0, 0.2, 1.0], [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.5]];
        for a in &actions {
            assert_eq!(env.step(a).unwrap(), 0.0);
            imagine.advance(a);
        }
        let want = [0.1, -0.025, 0.05, 0.0, 0.0, 0.1, -0.5];
        let got = env.observe().proprio;
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-6, "{got:?}");
        }
        assert_eq!(imagine.proprio(), got);
        // A dataset of these steps trains policies on the same vectors: step 0 reads the
        // initial (0, …, 0, −1), step 1 the first action's pose (0.05, −0.025, 0.05, 0, 0, 0.1, 1).
        let recorded = t.recorded_proprio(&[], &actions.map(|a| a.to_vec()));
        assert_eq!(recorded[0], vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0]);
        let first = [0.05, -0.025, 0.05, 0.0, 0.0, 0.1, 1.0];
        assert!(recorded[1].iter().zip(first).all(|(g, w)| (g - w).abs() < 1e-6), "{recorded:?}");
        assert_ne!(env.observe().frame, before, "the frame is rendered again after a step");
        let e = env.step(&[0.0; 2]).unwrap_err().to_string();
        assert_eq!(e, "action of 2 entries at seed 5: the task takes 7");
    }

    #[test]
    fn can_is_the_same_kind_of_task() {
        let t = RobosuiteTask::new(CanSim::new(CanConfig::default()).unwrap());
        assert_eq!(
            (t.name(), t.max_steps(), t.score_kind()),
            ("can", CanConfig::default().max_steps, ScoreKind::Success)
        );
        let env = t.reset(1).unwrap();
        assert_eq!(env.observe().frame.len(), 96 * 96 * 3);
        assert_eq!(env.final_state().len(), 3);
        // Labels name the object's position, then the end effector's and the fingers'.
        let labels = t.frame_labels();
        let names: Vec<&str> = labels.iter().map(|(_, n)| n.as_str()).collect();
        assert_eq!(
            names,
            ["object_x", "object_y", "object_z", "eef_x", "eef_y", "eef_z", "finger_1", "finger_2"]
        );
        let columns: Vec<usize> = labels.iter().map(|(i, _)| *i).collect();
        // Object (0..3), then the robot's columns from 7: eef 7..10, fingers 14, 15.
        assert_eq!(columns, [0, 1, 2, 7, 8, 9, 14, 15]);
    }
}
