//! What one scripted episode of a robosuite task is run with and gives back: the
//! perturbation of a behaviour's actions (Gaussian action noise, a control lag), its limits,
//! uniform random actions, the recorded rows and, on request, frames. The episode itself is
//! run by [`super::arm_sim::run`].
//!
//! The perturbation's random stream derives from the episode's seed and the
//! behaviour's name, so an episode is a pure function of its arguments whatever
//! thread runs it.

use harness::seed::{derive, fnv1a};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

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
