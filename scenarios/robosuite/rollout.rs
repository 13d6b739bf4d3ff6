//! Running one scripted episode of a robosuite task: a behaviour (a function of
//! the episode's state), its perturbation (Gaussian action noise, a control
//! lag), the recorded rows and, on request, frames.
//!
//! The perturbation's random stream derives from the episode's seed and the
//! behaviour's name, so an episode is a pure function of its arguments whatever
//! thread runs it.

use std::collections::VecDeque;

use harness::seed::{derive, fnv1a};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::episode::ArmEpisode;
use crate::error::ScenarioError;

/// What the runner needs of a task's episode.
pub trait TaskEpisode {
    /// The arm, the object and their state.
    fn arm(&self) -> &ArmEpisode;
    /// The arm, mutably (to step and render).
    fn arm_mut(&mut self) -> &mut ArmEpisode;
    /// The task's success check on the current state.
    fn success(&self) -> bool;
}

/// Noise and lag on a behaviour's actions.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Perturbation {
    /// Std of Gaussian noise added to the six arm entries (action units, clipped to [−1, 1]).
    pub noise: f64,
    /// Control steps by which actions arrive late (the first ones are a no-op with the gripper open).
    pub lag: usize,
}

/// One recorded control step.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Step index from 0.
    pub step: u32,
    /// The state row before the action.
    pub state: Vec<f64>,
    /// The action applied.
    pub action: [f64; 7],
    /// Success after the action.
    pub success: bool,
}

/// What an episode produced.
#[derive(Clone, Debug, Default)]
pub struct Recorded {
    /// The rows, one per step taken.
    pub rows: Vec<Row>,
    /// The state after the last step.
    pub final_state: Vec<f64>,
    /// Whether the task succeeded at any step.
    pub success: bool,
    /// The frame before each action and after the last one, when asked for.
    pub frames: Vec<Vec<u8>>,
}

/// How long an episode runs and what it records.
#[derive(Clone, Copy, Debug)]
pub struct RunLimits {
    /// Step limit.
    pub max_steps: usize,
    /// End at the first success.
    pub stop_at_success: bool,
    /// Side of the agentview frames to record, if any.
    pub frame_size: Option<usize>,
}

/// Uniform random actions in [−1, 1]⁷, a fresh one every 5 steps, seeded.
pub struct RandomActions {
    rng: ChaCha8Rng,
    held: [f64; 7],
    step: usize,
}

impl RandomActions {
    /// The random behaviour of episode `seed` of `scenario`.
    pub fn new(scenario: &str, seed: u64) -> Self {
        let rng = ChaCha8Rng::seed_from_u64(derive(seed, &[fnv1a(scenario), fnv1a("random-actions")]));
        Self { rng, held: [0.0; 7], step: 0 }
    }

    /// The next action.
    pub fn action(&mut self) -> [f64; 7] {
        if self.step.is_multiple_of(5) {
            self.held = std::array::from_fn(|_| self.rng.random_range(-1.0..=1.0));
        }
        self.step += 1;
        self.held
    }
}

/// Runs `ep` under `act` with `perturbation`; `stream` names the behaviour for
/// the noise's random stream.
///
/// # Errors
/// A step error (naming the seed and step), or a render failure.
pub fn run<E: TaskEpisode>(
    ep: &mut E,
    mut act: impl FnMut(&E) -> [f64; 7],
    perturbation: Perturbation,
    stream: &str,
    limits: RunLimits,
) -> Result<Recorded, ScenarioError> {
    let seed = ep.arm().seed();
    let mut rng = ChaCha8Rng::seed_from_u64(derive(seed, &[fnv1a("perturbation"), fnv1a(stream)]));
    let mut queue: VecDeque<[f64; 7]> = VecDeque::new();
    let mut out = Recorded::default();
    for step in 0..limits.max_steps {
        if let Some(s) = limits.frame_size {
            out.frames.push(ep.arm_mut().render(s)?);
        }
        let mut a = act(ep);
        if perturbation.noise > 0.0 {
            for v in &mut a[..6] {
                let n: f64 = rng.sample(StandardNormal);
                *v = (*v + perturbation.noise * n).clamp(-1.0, 1.0);
            }
        }
        if perturbation.lag > 0 {
            queue.push_back(a);
            a = if queue.len() > perturbation.lag {
                queue.pop_front().unwrap_or_default()
            } else {
                [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0]
            };
        }
        let state = ep.arm().state();
        ep.arm_mut().step(&a)?;
        let now = ep.success();
        out.success |= now;
        out.rows.push(Row { step: step as u32, state, action: a, success: now });
        if now && limits.stop_at_success {
            break;
        }
    }
    if let Some(s) = limits.frame_size {
        out.frames.push(ep.arm_mut().render(s)?);
    }
    out.final_state = ep.arm().state();
    Ok(out)
}

/// A finished episode of a task whose initial state is `I` and behaviours `B`.
#[derive(Clone, Debug)]
pub struct Episode<I, B> {
    /// The seed.
    pub seed: u64,
    /// The initial state.
    pub init: I,
    /// The behaviour.
    pub behaviour: B,
    /// The rows, one per step taken.
    pub rows: Vec<Row>,
    /// The state after the last step.
    pub final_state: Vec<f64>,
    /// Whether the task succeeded at any step.
    pub success: bool,
    /// The frame before each action and after the last one, when asked for.
    pub frames: Vec<Vec<u8>>,
}

impl<I, B> Episode<I, B> {
    /// Assembles an episode from what [`run`] recorded.
    pub fn new(seed: u64, init: I, behaviour: B, r: Recorded) -> Self {
        Self {
            seed,
            init,
            behaviour,
            rows: r.rows,
            final_state: r.final_state,
            success: r.success,
            frames: r.frames,
        }
    }
}

/// A robosuite task the data commands can run: its scripted behaviours and a
/// seeded episode.
pub trait ArmTask: Sync {
    /// The initial state an episode records.
    type Init: serde::Serialize + Clone + Send;
    /// Its scripted behaviours.
    type Behaviour: Copy + Send + Sync + PartialEq + 'static;
    /// The scenario's name (`lift`, `can`).
    fn name(&self) -> &'static str;
    /// The behaviours by name, the expert first.
    fn behaviours(&self) -> &'static [(&'static str, Self::Behaviour)];
    /// The state row's column names.
    fn state_columns(&self) -> Vec<&'static str>;
    /// The default step limit.
    fn max_steps(&self) -> usize;
    /// The config, for `config.json` and the dataset's attributes.
    fn config_json(&self) -> serde_json::Value;
    /// Runs episode `seed` under `behaviour`.
    ///
    /// # Errors
    /// A reset, step or render error naming the seed.
    fn episode(
        &self,
        seed: u64,
        behaviour: Self::Behaviour,
        perturbation: Perturbation,
        limits: RunLimits,
    ) -> Result<Episode<Self::Init, Self::Behaviour>, ScenarioError>;

    /// A behaviour's name.
    fn behaviour_name(&self, b: Self::Behaviour) -> &'static str {
        self.behaviours().iter().find(|(_, k)| *k == b).map_or("?", |(n, _)| n)
    }
}
