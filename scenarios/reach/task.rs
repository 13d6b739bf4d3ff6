//! Reach as a [`Task`]: its seeded episodes, its frames and the judge that reads them back.

use harness::judge::Judge;
use harness::seed::{derive, fnv1a};
use harness::task::{
    ActionKind, ActionSpec, Env, Imagination, ModelView, ObservationSpec, ScoreKind, Seen, Task, TaskError,
};

use super::ReachConfig;
use crate::error::ScenarioError;

/// The line's length: positions and targets lie in [0, LINE].
pub const LINE: f64 = 10.0;

/// The marker's band: white, this many pixels wide at 96 (scaled with the side).
const MARKER_WIDTH: usize = 6;
/// The goal's band: green, narrower, drawn under the marker.
const GOAL_WIDTH: usize = 4;

/// The column of position `x` in a frame of side `size`.
fn column(x: f64, size: usize) -> f64 {
    x.clamp(0.0, LINE) / LINE * (size - 1) as f64
}

/// The frame of a marker at `x` with the goal at `goal`: `size`² RGB, rows identical.
pub fn render(x: f64, goal: f64, size: usize) -> Vec<u8> {
    let band = |centre: f64, width: usize| {
        let half = (width * size).div_ceil(96) as f64 / 2.0;
        move |c: usize| (c as f64 - centre).abs() < half
    };
    let (marker, target) = (band(column(x, size), MARKER_WIDTH), band(column(goal, size), GOAL_WIDTH));
    let row: Vec<u8> = (0..size)
        .flat_map(|c| match (marker(c), target(c)) {
            (true, _) => [255, 255, 255],
            (false, true) => [0, 160, 0],
            (false, false) => [40, 40, 40],
        })
        .collect();
    row.repeat(size)
}

/// The judge of a Reach frame: success when the marker's band (the white pixels of the
/// middle row) is centred within the tolerance of the goal.
#[derive(Clone, Debug)]
pub struct ReachJudge {
    goal: f64,
    tolerance: f64,
}

impl ReachJudge {
    /// The marker's position a frame shows, from the mean column of its white pixels;
    /// `None` for a frame without one or of no square side.
    pub fn position(frame: &[u8]) -> Option<f64> {
        let size = (frame.len() as f64 / 3.0).sqrt().round() as usize;
        if size < 2 || size * size * 3 != frame.len() {
            return None;
        }
        let row = &frame[(size / 2) * size * 3..(size / 2 + 1) * size * 3];
        let white: Vec<usize> =
            (0..size).filter(|&c| row[c * 3..c * 3 + 3].iter().all(|&v| v > 200)).collect();
        if white.is_empty() {
            return None;
        }
        let mean = white.iter().sum::<usize>() as f64 / white.len() as f64;
        Some(mean / (size - 1) as f64 * LINE)
    }
}

impl Judge for ReachJudge {
    fn score(&self, frame: &[u8]) -> f64 {
        let near = Self::position(frame).is_some_and(|x| (x - self.goal).abs() < self.tolerance);
        if near { 1.0 } else { 0.0 }
    }
}

/// The Reach task of one scenario config.
pub struct ReachTask {
    pub(super) cfg: ReachConfig,
}

impl ReachTask {
    /// The task of `cfg`.
    pub fn new(cfg: ReachConfig) -> Self {
        Self { cfg }
    }

    /// Its parameters.
    pub fn config(&self) -> &ReachConfig {
        &self.cfg
    }

    /// Episode `seed` at its initial state (a pure function of the seed).
    pub fn episode(&self, seed: u64) -> ReachEnv {
        let u = (derive(seed, &[fnv1a("reach/start")]) >> 11) as f64 / (1u64 << 53) as f64;
        ReachEnv { seed, x: u * LINE, step: 0, cfg: self.cfg.clone() }
    }
}

impl Task for ReachTask {
    fn simulator(&self) -> &'static str {
        "simulator"
    }

    fn parameters(&self) -> Option<serde_json::Value> {
        serde_json::to_value(&self.cfg).ok()
    }

    fn name(&self) -> &str {
        "reach"
    }
    fn action_spec(&self) -> ActionSpec {
        ActionSpec { dim: 1, low: vec![0.0], high: vec![LINE as f32], kind: ActionKind::Absolute }
    }
    fn observation_spec(&self) -> ObservationSpec {
        ObservationSpec {
            image_size: self.cfg.image_size,
            cameras: vec!["line".into()],
            proprio: vec!["x".into()],
            robot: Vec::new(),
        }
    }
    fn score_kind(&self) -> ScoreKind {
        ScoreKind::Success
    }
    fn max_steps(&self) -> usize {
        self.cfg.max_steps
    }
    fn control_hz(&self) -> f64 {
        10.0
    }
    fn judges_own_frames(&self) -> bool {
        true
    }
    fn reset(&self, seed: u64) -> Result<Box<dyn Env>, TaskError> {
        Ok(Box::new(self.episode(seed)))
    }
    fn recorded_proprio(&self, states: &[Vec<f64>], _actions: &[Vec<f32>]) -> Vec<Vec<f32>> {
        states.iter().map(|s| vec![s.first().copied().unwrap_or(0.0) as f32]).collect()
    }
    fn frame_labels(&self) -> Vec<(usize, String)> {
        vec![(0, "x".into())]
    }
    fn scripted(&self) -> Option<&dyn harness::scripted::Scripted> {
        Some(self)
    }
}

/// One Reach episode.
#[derive(Clone, Debug)]
pub struct ReachEnv {
    seed: u64,
    x: f64,
    step: usize,
    cfg: ReachConfig,
}

impl ReachEnv {
    /// The marker's position.
    pub fn x(&self) -> f64 {
        self.x
    }

    /// The frame of the current state at side `size`.
    pub fn frame(&self, size: usize) -> Vec<u8> {
        render(self.x, self.cfg.goal, size)
    }

    /// Moves the marker toward `target` for one control step; returns the raw score after.
    ///
    /// # Errors
    /// A non-finite target, naming the seed and step.
    pub fn act(&mut self, target: f64) -> Result<f64, ScenarioError> {
        if !target.is_finite() {
            return Err(ScenarioError::BadAction {
                action: vec![target],
                seed: self.seed,
                step: self.step as u32,
            });
        }
        self.x += (target.clamp(0.0, LINE) - self.x) * self.cfg.gain;
        self.step += 1;
        Ok(Env::score(self))
    }
}

impl Env for ReachEnv {
    fn seed(&self) -> u64 {
        self.seed
    }
    fn observe(&self) -> Seen {
        Seen {
            frame: self.frame(self.cfg.image_size),
            proprio: vec![self.x as f32],
            robot: Vec::new(),
            exact: None,
            native: None,
        }
    }
    fn step(&mut self, action: &[f32]) -> Result<f64, TaskError> {
        let Some(&a) = action.first().filter(|_| action.len() == 1) else {
            let e = ScenarioError::BadActionSize { got: action.len(), expected: 1, seed: self.seed };
            return Err(TaskError::new(e));
        };
        Ok(self.act(f64::from(a))?)
    }
    fn score(&self) -> f64 {
        if (self.x - self.cfg.goal).abs() < self.cfg.tolerance { 1.0 } else { 0.0 }
    }
    fn state(&self) -> Vec<f64> {
        vec![self.x]
    }
    fn conditions(&self) -> Vec<(&'static str, f64)> {
        vec![("goal", self.cfg.goal)]
    }
    fn final_state(&self) -> Vec<(&'static str, f64)> {
        vec![("final_x", self.x)]
    }
    fn judge(&self) -> Option<Box<dyn Judge>> {
        Some(Box::new(ReachJudge { goal: self.cfg.goal, tolerance: self.cfg.tolerance }))
    }
    fn imagination(&self, _view: ModelView) -> Box<dyn Imagination> {
        Box::new(ReachImagination { first: self.observe().frame, x: self.x, gain: self.cfg.gain })
    }
}

/// The world model's view of a Reach episode: its first frame, and the position the
/// policy's commands move the marker to.
struct ReachImagination {
    first: Vec<u8>,
    x: f64,
    gain: f64,
}

impl Imagination for ReachImagination {
    fn first_frame(&self) -> &[u8] {
        &self.first
    }
    fn to_observation(&self, _frame: &mut [u8]) {}
    fn advance(&mut self, action: &[f32]) {
        if let Some(&a) = action.first().filter(|a| a.is_finite()) {
            self.x += (f64::from(a).clamp(0.0, LINE) - self.x) * self.gain;
        }
    }
    fn proprio(&self) -> Vec<f32> {
        vec![self.x as f32]
    }
}
