//! Push-T as a [`Task`]: what the paired engine drives.
//!
//! - Actions: 2-D absolute targets of the agent, in world units ([0, world size]²).
//! - Observation: one top-down 96x96 RGB frame (the rasteriser's) and the agent's
//!   position.
//! - Score: coverage c of the goal, exact from the state; reward clip(c / 0.95, 0, 1),
//!   success at c > 0.95 ([`ScoreKind::Coverage`]).
//! - Judge of imagined frames: the colour-mask [`FrameScorer`] for the episode's goal.
//! - Imagination: the world model starts from the first frame (rendered without the
//!   goal for goal-free models, which get the goal drawn back onto every decoded
//!   frame); the policy reads the last commanded target as the agent's position.

use std::path::Path;
use std::sync::Arc;

use harness::judge::Judge;
use harness::policy::Policy;
use harness::task::{
    ActionKind, ActionSpec, Env, Imagination, ModelView, ObservationSpec, PlanCost, PoseColumns, ScoreKind,
    Seen, Task, TaskError,
};
use mujoco_rs::prelude::MjModel;

use super::frame_score::FrameScorer;
use super::plan_cost::GoalDistance;
use super::render::Rasterizer;
use super::scripted::ScriptedPolicy;
use super::{PushTConfig, PushTEnv, PushTPhysics};
use crate::error::ScenarioError;

/// The Push-T task of one scenario config, with its compiled model.
pub struct PushTTask {
    cfg: PushTConfig,
    model: Arc<MjModel>,
    raster: Rasterizer,
}

impl PushTTask {
    /// Compiles the scene of `cfg`.
    ///
    /// # Errors
    /// A scene MuJoCo refuses.
    pub fn new(cfg: PushTConfig) -> Result<Self, ScenarioError> {
        let model = PushTPhysics::compile(&cfg)?;
        let raster = Rasterizer::new(&cfg);
        Ok(Self { cfg, model, raster })
    }

    /// The scenario config.
    pub fn config(&self) -> &PushTConfig {
        &self.cfg
    }

    /// The compiled MuJoCo model.
    pub fn model(&self) -> &Arc<MjModel> {
        &self.model
    }
}

impl Task for PushTTask {
    fn name(&self) -> &str {
        "pusht"
    }

    fn parameters(&self) -> Option<serde_json::Value> {
        serde_json::to_value(&self.cfg).ok()
    }

    fn pose_labels(&self) -> Option<PoseColumns> {
        // `collect`'s state columns: agent x, y; block x, y, θ; goal x, y, θ.
        Some(PoseColumns { object: [2, 3, 4], goal: [5, 6, 7] })
    }

    fn action_spec(&self) -> ActionSpec {
        let size = self.cfg.world.size as f32;
        ActionSpec { dim: 2, low: vec![0.0; 2], high: vec![size; 2], kind: ActionKind::Absolute }
    }

    fn observation_spec(&self) -> ObservationSpec {
        ObservationSpec {
            image_size: self.raster.size(),
            cameras: vec!["top".into()],
            proprio: vec!["agent_x".into(), "agent_y".into()],
            robot: Vec::new(),
        }
    }

    fn judges_own_frames(&self) -> bool {
        // Every episode's `judge` is its frame scorer (goal mask × block colour).
        true
    }

    fn score_kind(&self) -> ScoreKind {
        ScoreKind::Coverage { success_at: self.cfg.task.success_coverage }
    }

    fn max_steps(&self) -> usize {
        self.cfg.task.max_steps as usize
    }

    fn control_hz(&self) -> f64 {
        f64::from(self.cfg.timing.control_hz)
    }

    fn reset(&self, seed: u64) -> Result<Box<dyn Env>, TaskError> {
        let mut env = PushTEnv::new(self.model.clone(), &self.cfg);
        env.reset(seed).map_err(TaskError::new)?;
        Ok(Box::new(PushTEpisode { env, raster: self.raster.clone() }))
    }

    fn recorded_proprio(&self, states: &[Vec<f64>], _actions: &[Vec<f32>]) -> Vec<Vec<f32>> {
        // The agent's position: the state's first two columns, as `observe` reads it.
        states.iter().map(|s| s.iter().take(2).map(|&v| v as f32).collect()).collect()
    }

    fn scripted_policy(&self, dir: &Path) -> Result<Box<dyn Policy>, TaskError> {
        let p = ScriptedPolicy::load(dir, &self.cfg, self.model.clone(), self.raster.size())
            .map_err(TaskError::new)?;
        Ok(Box::new(p))
    }

    fn scripted(&self) -> Option<&dyn harness::scripted::Scripted> {
        Some(self)
    }
}

/// One Push-T episode behind the task interface.
pub struct PushTEpisode {
    env: PushTEnv,
    raster: Rasterizer,
}

impl PushTEpisode {
    /// The underlying environment.
    pub fn env(&self) -> &PushTEnv {
        &self.env
    }
}

impl Env for PushTEpisode {
    fn seed(&self) -> u64 {
        self.env.seed()
    }

    fn observe(&self) -> Seen {
        let st = self.env.state();
        Seen {
            frame: self.raster.render(&st, &self.env.goal()),
            proprio: st.agent.map(|v| v as f32).to_vec(),
            robot: Vec::new(),
            exact: None,
            native: None,
        }
    }

    fn step(&mut self, action: &[f32]) -> Result<f64, TaskError> {
        let &[x, y] = action else {
            return Err(TaskError::new(ScenarioError::BadActionSize {
                seed: self.env.seed(),
                expected: 2,
                got: action.len(),
            }));
        };
        let sc = self.env.step([f64::from(x), f64::from(y)]).map_err(TaskError::new)?;
        Ok(sc.coverage)
    }

    fn score(&self) -> f64 {
        self.env.score().coverage
    }

    fn state(&self) -> Vec<f64> {
        let st = self.env.state();
        vec![st.agent[0], st.agent[1], st.block.x, st.block.y, st.block.theta]
    }

    fn conditions(&self) -> Vec<(&'static str, f64)> {
        let [x, y, theta] = self.env.goal().to_array();
        vec![("goal_x", x), ("goal_y", y), ("goal_theta", theta)]
    }

    fn final_state(&self) -> Vec<(&'static str, f64)> {
        let [x, y, theta] = self.env.state().block.to_array();
        vec![("final_block_x", x), ("final_block_y", y), ("final_block_theta", theta)]
    }

    fn goal_pose(&self) -> Option<[f64; 3]> {
        Some(self.env.goal().to_array())
    }

    fn judge(&self) -> Option<Box<dyn Judge>> {
        Some(Box::new(self.scorer()))
    }

    fn imagination(&self, view: ModelView) -> Box<dyn Imagination> {
        let goal_free = (view == ModelView::GoalFree).then(|| self.scorer());
        let last = self.env.state().agent.map(|v| v as f32);
        Box::new(PushTImagination { first: self.model_frame(view), goal_free, last })
    }

    fn model_frame(&self, view: ModelView) -> Vec<u8> {
        let st = self.env.state();
        match view {
            ModelView::Observation => self.raster.render(&st, &self.env.goal()),
            ModelView::GoalFree => self.raster.render_without_goal(&st),
        }
    }

    fn fork(&self) -> Option<Box<dyn Env>> {
        Some(Box::new(PushTEpisode { env: self.env.fork(), raster: self.raster.clone() }))
    }

    fn plan_cost(&self) -> Option<Box<dyn PlanCost>> {
        Some(Box::new(GoalDistance::new(self.env.config(), &self.env.goal(), self.raster.size())))
    }
}

impl PushTEpisode {
    fn scorer(&self) -> FrameScorer {
        FrameScorer::new(self.env.config(), &self.env.goal(), self.raster.size())
    }
}

/// What the imagined branch knows of a Push-T episode.
struct PushTImagination {
    /// The first frame in the model's view.
    first: Vec<u8>,
    /// For a goal-free model: the scorer that draws the goal back.
    goal_free: Option<FrameScorer>,
    /// The last commanded target (at first, the agent's starting position).
    last: [f32; 2],
}

impl Imagination for PushTImagination {
    fn first_frame(&self) -> &[u8] {
        &self.first
    }

    fn to_observation(&self, frame: &mut [u8]) {
        if let Some(s) = &self.goal_free {
            s.draw_goal(frame);
        }
    }

    fn advance(&mut self, action: &[f32]) {
        if let &[x, y] = action {
            self.last = [x, y];
        }
    }

    fn proprio(&self) -> Vec<f32> {
        self.last.to_vec()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn task() -> PushTTask {
        PushTTask::new(PushTConfig::default()).unwrap()
    }

    #[test]
    fn episodes_reset_as_a_pure_function_of_the_seed_and_step_as_the_env() {
        let t = task();
        let (a, b) = (t.reset(100_003).unwrap(), t.reset(100_003).unwrap());
        assert_eq!(a.observe(), b.observe());
        assert_eq!(a.state(), b.state());
        assert_ne!(a.state(), t.reset(100_004).unwrap().state());
        // The interface steps exactly as PushTEnv does: same coverage after each action.
        let mut ep = t.reset(7).unwrap();
        let mut env = PushTEnv::new(t.model().clone(), t.config());
        env.reset(7).unwrap();
        for target in [[200.0f32, 220.0], [260.0, 300.0], [300.0, 310.0]] {
            let raw = ep.step(&target).unwrap();
            let exact = env.step(target.map(f64::from)).unwrap().coverage;
            assert_eq!(raw, exact);
            assert_eq!(ep.score(), exact);
        }
        // The state row: agent x, y, block x, y, θ.
        let st = env.state();
        assert_eq!(ep.state(), vec![st.agent[0], st.agent[1], st.block.x, st.block.y, st.block.theta]);
        assert_eq!(ep.observe().proprio, vec![st.agent[0] as f32, st.agent[1] as f32]);
    }

    #[test]
    fn a_wrong_sized_action_is_an_error_naming_the_seed() {
        let mut ep = task().reset(5).unwrap();
        let e = ep.step(&[1.0, 2.0, 3.0]).unwrap_err().to_string();
        assert_eq!(e, "action of 3 entries at seed 5: the task takes 2");
    }

    #[test]
    fn the_imagination_starts_from_the_observation_and_reads_commands() {
        let t = task();
        let ep = t.reset(11).unwrap();
        let first = ep.observe();
        let mut im = ep.imagination(ModelView::Observation);
        assert_eq!(im.first_frame(), &first.frame[..]);
        // Before any command the agent's starting position, then the last commanded target.
        assert_eq!(im.proprio(), first.proprio);
        im.advance(&[10.0, 20.0]);
        im.advance(&[30.0, 40.0]);
        assert_eq!(im.proprio(), vec![30.0, 40.0]);
        // Goal-free: the model's first frame lacks the goal (fewer dark pixels); drawing
        // it back restores the observation on every pixel fully inside or outside the
        // goal, so at most the anti-aliased rim differs (under 5% of the pixels here).
        let free = ep.imagination(ModelView::GoalFree);
        let mut back = free.first_frame().to_vec();
        assert_ne!(back, first.frame);
        free.to_observation(&mut back);
        let differ = back.iter().zip(&first.frame).filter(|(a, b)| a.abs_diff(**b) > 2).count();
        assert!(differ * 20 < first.frame.len(), "{differ} of {} bytes differ", first.frame.len());
    }

    #[test]
    fn declares_its_spaces_and_score() {
        let t = task();
        let a = t.action_spec();
        assert_eq!((a.dim, a.kind, a.high[0]), (2, ActionKind::Absolute, 512.0));
        assert_eq!(t.observation_spec().image_size, 96);
        assert_eq!(t.score_kind(), ScoreKind::Coverage { success_at: 0.95 });
        assert_eq!((t.max_steps(), t.control_hz()), (300, 10.0));
    }
}
