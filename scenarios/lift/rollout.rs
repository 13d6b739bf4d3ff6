//! Running one scripted Lift episode: a behaviour, its perturbation (Gaussian
//! action noise, a control lag), the recorded rows and, on request, frames.
//!
//! Every random stream derives from the episode's seed, so an episode is a pure
//! function of (config, behaviour, perturbation, seed) whatever thread runs it.

use std::collections::VecDeque;

use harness::seed::{derive, fnv1a};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::expert::{LiftExpert, LiftFlaws};
use super::sim::{LiftInit, LiftSim};
use crate::error::ScenarioError;

/// The scripted Lift behaviours.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LiftBehaviour {
    /// The privileged-state expert.
    Expert,
    /// The expert aiming 3 cm beside the cube: it closes on nothing.
    Miss,
    /// The expert stopping and opening the gripper once the cube is 0.015 m up,
    /// short of the 0.04 m that counts.
    Drop,
    /// The expert coming down beside the cube with the gripper closed and shoving it.
    Push,
    /// The expert standing still 15 steps before every phase.
    Hesitate,
    /// Uniform random actions in [−1, 1]⁷, a fresh one every 5 steps.
    Random,
}

impl LiftBehaviour {
    /// Every behaviour, by name.
    pub const ALL: [(&'static str, LiftBehaviour); 6] = [
        ("expert", Self::Expert),
        ("miss", Self::Miss),
        ("drop", Self::Drop),
        ("push", Self::Push),
        ("hesitate", Self::Hesitate),
        ("random", Self::Random),
    ];

    /// Parses a name.
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.iter().find(|(n, _)| *n == name).map(|(_, b)| *b)
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        Self::ALL.iter().find(|(_, b)| *b == self).map_or("?", |(n, _)| n)
    }

    fn flaws(self) -> LiftFlaws {
        match self {
            Self::Miss => LiftFlaws { aim_offset: 0.03, ..LiftFlaws::default() },
            Self::Drop => LiftFlaws { drop_height: 0.015, ..LiftFlaws::default() },
            Self::Push => LiftFlaws { push: true, ..LiftFlaws::default() },
            Self::Hesitate => LiftFlaws { hesitate: 15, ..LiftFlaws::default() },
            Self::Expert | Self::Random => LiftFlaws::default(),
        }
    }
}

/// Noise and lag on the behaviour's actions.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LiftPerturbation {
    /// Std of Gaussian noise added to the six arm entries (action units, clipped to [−1, 1]).
    pub noise: f64,
    /// Control steps by which actions arrive late (the first ones repeat the no-op).
    pub lag: usize,
}

/// One recorded control step.
#[derive(Clone, Debug, PartialEq)]
pub struct LiftRow {
    /// Step index from 0.
    pub step: u32,
    /// The state row before the action ([`super::STATE_COLUMNS`]).
    pub state: Vec<f64>,
    /// The action applied.
    pub action: [f64; 7],
    /// Success after the action.
    pub success: bool,
}

/// A finished episode.
#[derive(Clone, Debug)]
pub struct LiftEpisodeRecord {
    /// The seed.
    pub seed: u64,
    /// The initial state.
    pub init: LiftInit,
    /// The behaviour.
    pub behaviour: LiftBehaviour,
    /// The rows, one per step taken.
    pub rows: Vec<LiftRow>,
    /// The state after the last step.
    pub final_state: Vec<f64>,
    /// Whether the cube was lifted at any step.
    pub success: bool,
    /// The frame before each action and after the last one, when asked for.
    pub frames: Vec<Vec<u8>>,
}

/// Runs episode `seed` for at most `max_steps` steps, ending at the first
/// success when `stop_at_success`; `frame_size` asks for agentview frames of
/// that side.
///
/// # Errors
/// A reset or step error (naming the seed and step), or a render failure.
pub fn run_lift_episode(
    sim: &LiftSim,
    behaviour: LiftBehaviour,
    perturbation: LiftPerturbation,
    seed: u64,
    max_steps: usize,
    stop_at_success: bool,
    frame_size: Option<usize>,
) -> Result<LiftEpisodeRecord, ScenarioError> {
    let mut ep = sim.reset(seed)?;
    let mut expert = LiftExpert::new(behaviour.flaws());
    let mut rng =
        ChaCha8Rng::seed_from_u64(derive(seed, &[fnv1a("lift/behaviour"), fnv1a(behaviour.name())]));
    let mut held = [0.0; 7];
    let mut queue: VecDeque<[f64; 7]> = VecDeque::new();
    let mut rows = Vec::new();
    let mut frames = Vec::new();
    let mut success = false;
    for step in 0..max_steps {
        if let Some(s) = frame_size {
            frames.push(ep.render(s)?);
        }
        let mut a = match behaviour {
            LiftBehaviour::Random => {
                if step % 5 == 0 {
                    held = std::array::from_fn(|_| rng.random_range(-1.0..=1.0));
                }
                held
            }
            _ => expert.act(&ep),
        };
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
        let state = ep.state();
        ep.step(&a)?;
        let now = ep.success();
        success |= now;
        rows.push(LiftRow { step: step as u32, state, action: a, success: now });
        if now && stop_at_success {
            break;
        }
    }
    if let Some(s) = frame_size {
        frames.push(ep.render(s)?);
    }
    Ok(LiftEpisodeRecord {
        seed,
        init: *ep.init(),
        behaviour,
        rows,
        final_state: ep.state(),
        success,
        frames,
    })
}
