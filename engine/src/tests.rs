//! The engine on a task that is not Push-T: a toy "reach" task scored by success
//! alone (as robomimic's Lift and Can are), with 1-D actions and a 1-D proprioceptive
//! vector, to show that nothing in the simulator branch assumes Push-T's coverage or
//! its 2-D positions.

use harness::judge::Judge;
use harness::policy::{ActionChunk, Observation, Policy, PolicyError};
use harness::results::Branch;
use harness::rng::Rng;
use harness::task::{
    ActionKind, ActionSpec, Env, Imagination, ModelView, ObservationSpec, ScoreKind, Seen, Task, TaskError,
};

use world_model::action::ActionScale;
use world_model::codec::FrameCodec;
use world_model::model::{WorldModel, WorldModelConfig};
use world_model::unet::UNetConfig;

use crate::{EngineError, Setup, Start, Timing, replay_in_sim, sim_branch};

/// An agent on a line moves halfway to its commanded target each step; it succeeds
/// within 0.5 of the goal at 7. The frame's first byte shows the position × 25.
struct Reach;

struct ReachEnv {
    seed: u64,
    x: f64,
}

const GOAL: f64 = 7.0;

fn near(x: f64) -> f64 {
    if (x - GOAL).abs() < 0.5 { 1.0 } else { 0.0 }
}

impl Task for Reach {
    fn name(&self) -> &str {
        "reach"
    }
    fn action_spec(&self) -> ActionSpec {
        ActionSpec { dim: 1, low: vec![0.0], high: vec![10.0], kind: ActionKind::Absolute }
    }
    fn observation_spec(&self) -> ObservationSpec {
        ObservationSpec {
            image_size: 1,
            cameras: vec!["line".into()],
            proprio: vec!["x".into()],
            robot: Vec::new(),
        }
    }
    fn score_kind(&self) -> ScoreKind {
        ScoreKind::Success
    }
    fn max_steps(&self) -> usize {
        10
    }
    fn control_hz(&self) -> f64 {
        1.0
    }
    fn judges_own_frames(&self) -> bool {
        true
    }
    fn reset(&self, seed: u64) -> Result<Box<dyn Env>, TaskError> {
        Ok(Box::new(ReachEnv { seed, x: 3.0 * seed as f64 }))
    }
    fn recorded_proprio(&self, states: &[Vec<f64>], _actions: &[Vec<f32>]) -> Vec<Vec<f32>> {
        states.iter().map(|s| vec![s[0] as f32]).collect()
    }
}

/// Reads the position back from the frame.
struct ReachJudge;

impl Judge for ReachJudge {
    fn score(&self, frame: &[u8]) -> f64 {
        near(f64::from(frame[0]) / 25.0)
    }
}

impl Env for ReachEnv {
    fn seed(&self) -> u64 {
        self.seed
    }
    fn observe(&self) -> Seen {
        Seen {
            frame: vec![(self.x * 25.0) as u8, 0, 0],
            proprio: vec![self.x as f32],
            robot: Vec::new(),
            exact: None,
            native: None,
        }
    }
    fn step(&mut self, action: &[f32]) -> Result<f64, TaskError> {
        self.x += (f64::from(action[0]) - self.x) / 2.0;
        Ok(self.score())
    }
    fn score(&self) -> f64 {
        near(self.x)
    }
    fn state(&self) -> Vec<f64> {
        vec![self.x]
    }
    fn judge(&self) -> Option<Box<dyn Judge>> {
        Some(Box::new(ReachJudge))
    }
    fn imagination(&self, _: ModelView) -> Box<dyn Imagination> {
        unreachable!("the simulator branch never imagines")
    }
}

/// Commands the goal, two actions a decision.
struct ToGoal;

impl Policy for ToGoal {
    fn name(&self) -> &str {
        "to-goal"
    }
    fn obs_horizon(&self) -> usize {
        1
    }
    fn action_horizon(&self) -> usize {
        2
    }
    fn act(&self, obs: &[Observation], _: &mut [Rng]) -> Result<Vec<ActionChunk>, PolicyError> {
        assert!(obs.iter().flat_map(|o| &o.proprio).all(|p| p.len() == 1), "1-D proprioception");
        Ok(obs.iter().map(|_| vec![vec![GOAL as f32]; 2]).collect())
    }
}

#[test]
fn a_success_scored_task_runs_through_the_simulator_branch() {
    let setup = Setup::new(&Reach, 0, 10, None);
    let mut start = Start::new("to-goal", &[0, 2, 4], &setup).unwrap();
    start.trajectories = true;
    let out = sim_branch(&ToGoal, start, &setup, &mut Timing::default()).unwrap();
    // Seed 0 starts at 0: 3.5, 5.25, 6.125, 6.5625 — within 0.5 of 7 at step 4, the end of
    // the second chunk. Seed 2 starts at 6: 6.5 (not < 0.5 away), 6.75 — success at step 2.
    // Seed 4 starts at 12: 9.5, 8.25, 7.625, 7.3125 — step 4 as well.
    let r = &out.rows;
    assert_eq!((r[0].steps, r[1].steps, r[2].steps), (4, 2, 4));
    assert!(r.iter().all(|r| r.success && r.score == 1.0 && r.branch == Branch::Sim));
    // The trace holds the score at each chunk's end, repeated after success.
    assert_eq!(r[0].score_trace, vec![0.0, 1.0]);
    assert_eq!(r[1].score_trace, vec![1.0, 1.0]);
    // The judge reads the frame exactly here (x × 25 truncated keeps x within 0.04):
    // no error on the frames the policy saw.
    assert_eq!(r[0].scorer_abs_error, Some(0.0));
    // No named state: the task names none; no scene checks: its judge makes none.
    assert!(r[0].state.is_empty() && r[0].scene.is_empty());
    // Whole trajectories: the state before each action, the actions, the raw scores.
    let t = &out.episodes[0];
    assert_eq!(t.states, vec![vec![0.0], vec![3.5], vec![5.25], vec![6.125]]);
    assert_eq!(t.raw, vec![0.0, 0.0, 0.0, 1.0]);
    assert_eq!((t.frames.len(), t.actions.len(), t.success), (5, 4, true));
}

#[test]
fn recorded_actions_replayed_in_the_simulator_give_the_recorded_rows() {
    let setup = Setup::new(&Reach, 0, 10, None);
    let mut start = Start::new("to-goal", &[0, 2, 1], &setup).unwrap();
    start.trajectories = true;
    let out = sim_branch(&ToGoal, start, &setup, &mut Timing::default()).unwrap();
    for (t, row) in out.episodes.iter().zip(&out.rows) {
        let (r, none) = replay_in_sim(
            "to-goal",
            (1, 2),
            t.seed,
            t.actions.clone(),
            (&setup, false),
            &mut Timing::default(),
        )
        .unwrap();
        assert_eq!((r.seed, r.steps, r.success, r.score), (row.seed, row.steps, row.success, row.score));
        assert!(none.is_none());
    }
    // Seed 1 starts at 3: 5, 6, 6.5 (not < 0.5 from 7), 6.75: success at step 4.
    assert_eq!((out.rows[2].steps, out.rows[2].success), (4, true));
    // Other actions from the same state: seed 2 starts at 6 and is sent to 0 (3, 1.5):
    // a failure after the 2 replayed steps.
    let replay = |seed, actions| {
        replay_in_sim("to-goal", (1, 2), seed, actions, (&setup, false), &mut Timing::default())
    };
    let (r, _) = replay(2, vec![vec![0.0]; 2]).unwrap();
    assert_eq!((r.steps, r.success), (2, false));
    // Seed 0's actions cut after 2 steps (3.5, 5.25) fail too.
    let (r, _) = replay(0, vec![vec![7.0]; 2]).unwrap();
    assert_eq!((r.steps, r.success), (2, false));
    assert!(replay(0, Vec::new()).is_err());
}

#[test]
fn a_recorded_replay_comes_back_whole_with_the_same_row() {
    // Seed 1 starts at 3; actions to 7 step 5, 6, 6.5, 6.75: within 0.5 of the goal (7)
    // after step 4, the end of the second chunk of 2, where the episode ends.
    let setup = Setup::new(&Reach, 0, 10, None);
    let replay = |record| {
        replay_in_sim("to-goal", (1, 2), 1, vec![vec![7.0]; 6], (&setup, record), &mut Timing::default())
    };
    let (row, none) = replay(false).unwrap();
    let (recorded_row, t) = replay(true).unwrap();
    assert!(none.is_none());
    assert_eq!((row.steps, row.success), (4, true));
    assert_eq!(
        (recorded_row.steps, recorded_row.success, recorded_row.score),
        (row.steps, row.success, row.score)
    );
    let t = t.unwrap();
    assert_eq!((t.seed, t.actions.len(), t.frames.len(), t.success), (1, 4, 5, true));
    assert_eq!(t.states, vec![vec![3.0], vec![5.0], vec![6.0], vec![6.5]]);
    assert_eq!(t.raw, vec![0.0, 0.0, 0.0, 1.0]);
}

#[test]
fn episodes_that_never_succeed_run_to_the_step_limit() {
    // Seed 1 starts at 3 and is commanded to the goal; with max_steps 2 it reaches 5 then 6:
    // never within 0.5, so the row is a failure after exactly 2 steps.
    let setup = Setup::new(&Reach, 0, 2, None);
    let start = Start::new("to-goal", &[1], &setup).unwrap();
    let out = sim_branch(&ToGoal, start, &setup, &mut Timing::default()).unwrap();
    let r = &out.rows[0];
    assert_eq!((r.steps, r.success, r.score, r.max_raw), (2, false, 0.0, 0.0));
}

/// Raises the end effector, gripper open, two actions a decision; checks what it sees.
struct Up;

impl Policy for Up {
    fn name(&self) -> &str {
        "up"
    }
    fn obs_horizon(&self) -> usize {
        1
    }
    fn action_horizon(&self) -> usize {
        2
    }
    fn act(&self, obs: &[Observation], _: &mut [Rng]) -> Result<Vec<ActionChunk>, PolicyError> {
        for o in obs {
            assert_eq!((o.size, o.frames[0].len(), o.proprio[0].len()), (96, 96 * 96 * 3, 7));
        }
        Ok(obs.iter().map(|_| vec![vec![0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0]; 2]).collect())
    }
}

/// Says nothing succeeded.
struct Never;

impl Judge for Never {
    fn score(&self, _: &[u8]) -> f64 {
        0.0
    }
}

#[test]
fn robomimic_lift_runs_through_the_simulator_branch_with_a_given_judge() {
    let task = scenarios::load_task("lift").expect("robosuite assets (scripts/setup.sh)");
    // Lift has no hand-written judge of frames: without one given, the simulator branch
    // runs (scored exactly, no judge error to report) and the world-model branch refuses.
    let bare = Setup::new(task.as_ref(), 0, 4, None);
    let start = Start::new("up", &[0], &bare).unwrap();
    let wm = WorldModel::from_parts(
        WorldModelConfig::pixels(
            UNetConfig { action_dim: 7, ..UNetConfig::new(3, 8, vec![1], vec![]).with_groups(4) },
            96,
        ),
        FrameCodec::pixels(96),
        UNetConfig { action_dim: 7, ..UNetConfig::new(3, 8, vec![1], vec![]).with_groups(4) }
            .init(&burn::tensor::Device::flex()),
        &burn::tensor::Device::flex(),
    );
    let e = crate::wm_branch(&Up, &start, &bare, &wm, &mut Timing::default()).err().unwrap().to_string();
    assert!(e.contains("task lift has no hand-written judge"), "{e}");
    let alone = sim_branch(&Up, start, &bare, &mut Timing::default()).unwrap();
    assert_eq!((alone.rows[0].steps, alone.rows[0].scorer_abs_error), (4, None));
    let never: std::sync::Arc<dyn Judge> = std::sync::Arc::new(Never);
    let setup = Setup { judge: Some(&never), ..bare };
    let mut start = Start::new("up", &[0], &setup).unwrap();
    start.trajectories = true;
    // The imagined branch on a tiny random pixel-space model that reads 7-D actions in
    // [-1, 1]; one that reads Push-T's 2-D targets is refused, naming both widths.
    let device = burn::tensor::Device::flex();
    let unet = UNetConfig { action_dim: 7, ..UNetConfig::new(3, 8, vec![1], vec![]).with_groups(4) };
    let mut cfg = WorldModelConfig::pixels(unet, 96);
    let pusht = WorldModel::from_parts(cfg.clone(), FrameCodec::pixels(96), cfg.unet.init(&device), &device);
    let e = crate::wm_branch(&Up, &start, &setup, &pusht, &mut Timing::default()).err().unwrap();
    let source = std::error::Error::source(&e).map(ToString::to_string).unwrap_or_default();
    assert_eq!(source, "actions have 7 entries, the world model reads 2", "{e:?}");
    cfg.actions = Some(ActionScale { low: vec![-1.0; 7], high: vec![1.0; 7] });
    let wm = WorldModel::from_parts(cfg.clone(), FrameCodec::pixels(96), cfg.unet.init(&device), &device);
    let imagined = crate::wm_branch(&Up, &start, &setup, &wm, &mut Timing::default()).unwrap();
    for r in &imagined.rows {
        assert_eq!((r.branch, r.steps, r.success), (Branch::WorldModel, 4, false));
    }
    // The imagined episode's executed actions (Up's, two chunks of 2), and nothing exact.
    let e = &imagined.episodes[0];
    assert_eq!((e.seed, e.success, e.actions.len()), (0, false, 4));
    assert_eq!(e.actions[3], vec![0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0]);
    assert!(e.frames.is_empty() && e.states.is_empty() && e.raw.is_empty());
    // Replayed in MuJoCo they step as the policy's own rollout below does: 4 steps, no lift.
    let (replayed, _) =
        replay_in_sim("up", (1, 2), 0, e.actions.clone(), (&setup, false), &mut Timing::default()).unwrap();
    assert_eq!((replayed.steps, replayed.success, replayed.score), (4, false, 0.0));
    let out = sim_branch(&Up, start, &setup, &mut Timing::default()).unwrap();
    // Four steps of moving up with an open gripper never lift the cube.
    for r in &out.rows {
        assert_eq!((r.steps, r.success, r.score), (4, false, 0.0));
        // The judge said 0 on real frames whose exact score is 0.
        assert_eq!(r.scorer_abs_error, Some(0.0));
    }
    let t = &out.episodes[0];
    // A frame before each of the 4 actions, then the final one.
    assert_eq!((t.frames.len(), t.states[0].len(), t.actions[0].len()), (5, 23, 7));
    // The end effector rose: column 9 of the state is its height.
    assert!(t.states[3][9] > t.states[0][9], "{} -> {}", t.states[0][9], t.states[3][9]);
}

/// Commands the goal when the frame shows the agent anywhere but at 0, else 0.
struct GoIfSeen;

impl Policy for GoIfSeen {
    fn name(&self) -> &str {
        "go-if-seen"
    }
    fn obs_horizon(&self) -> usize {
        1
    }
    fn action_horizon(&self) -> usize {
        2
    }
    fn act(&self, obs: &[Observation], _: &mut [Rng]) -> Result<Vec<ActionChunk>, PolicyError> {
        let target = |o: &Observation| if o.frames[0][0] > 0 { GOAL as f32 } else { 0.0 };
        Ok(obs.iter().map(|o| vec![vec![target(o)]; 2]).collect())
    }
}

#[test]
fn the_policy_sees_the_rewritten_frames_and_the_scores_stay_exact() {
    let setup = Setup::new(&Reach, 0, 4, None);
    // Seed 2 starts at 6 (frame byte 150): seen as is, the policy commands 7 and the agent
    // reaches 6.5, then 6.75: success at step 2.
    let start = Start::new("go-if-seen", &[2], &setup).unwrap();
    let out = sim_branch(&GoIfSeen, start, &setup, &mut Timing::default()).unwrap();
    assert_eq!((out.rows[0].steps, out.rows[0].success), (2, true));
    // Every frame blanked before the policy sees it, the first one included: it commands
    // 0 throughout, 6 → 3 → 1.5 → 0.75 → 0.375, never within 0.5 of 7 in 4 steps. The hook
    // sees the first frame and the last frame of each of the 2 chunks: 3 frames.
    let seen = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let counter = seen.clone();
    let mut start = Start::new("go-if-seen", &[2], &setup).unwrap();
    start.trajectories = true;
    start.observe = Some(std::sync::Arc::new(move |frames: &mut [Vec<u8>]| {
        counter.fetch_add(frames.len(), std::sync::atomic::Ordering::SeqCst);
        frames.iter_mut().for_each(|f| f.fill(0));
    }));
    let out = sim_branch(&GoIfSeen, start, &setup, &mut Timing::default()).unwrap();
    let r = &out.rows[0];
    assert_eq!((r.steps, r.success), (4, false));
    assert_eq!(out.episodes[0].states, vec![vec![6.0], vec![3.0], vec![1.5], vec![0.75]]);
    assert_eq!(seen.load(std::sync::atomic::Ordering::SeqCst), 3);
    // The judge read the real frames (x × 25), which it reads exactly.
    assert_eq!(r.scorer_abs_error, Some(0.0));
    // The recorded trajectory keeps the real frames (6 × 25 = 150 first).
    assert_eq!(out.episodes[0].frames[0][0], 150);
}

/// A judge whose weights went non-finite: its scores are NaN.
struct Broken;

impl Judge for Broken {
    fn score(&self, _: &[u8]) -> f64 {
        f64::NAN
    }
}

#[test]
fn a_judge_scoring_nan_stops_the_imagined_branch_by_name() {
    // At 92f9f2b a learned judge with non-finite weights read +inf logits as sure
    // successes and NaN as failures, and the run went on: every imagined row was wrong.
    let task = scenarios::load_task("lift").expect("robosuite assets (scripts/setup.sh)");
    let broken: std::sync::Arc<dyn Judge> = std::sync::Arc::new(Broken);
    let setup = Setup::new(task.as_ref(), 0, 2, Some(&broken));
    let start = Start::new("up", &[7], &setup).unwrap();
    let device = burn::tensor::Device::flex();
    let unet = UNetConfig { action_dim: 7, ..UNetConfig::new(3, 8, vec![1], vec![]).with_groups(4) };
    let mut cfg = WorldModelConfig::pixels(unet, 96);
    cfg.actions = Some(ActionScale { low: vec![-1.0; 7], high: vec![1.0; 7] });
    let wm = WorldModel::from_parts(cfg.clone(), FrameCodec::pixels(96), cfg.unet.init(&device), &device);
    let e = crate::wm_branch(&Up, &start, &setup, &wm, &mut Timing::default()).err().unwrap();
    assert!(matches!(e, EngineError::Judge { seed: 7, .. }), "{e:?}");
    assert!(e.to_string().contains("policy up's episode 7 as NaN"), "{e}");
}
