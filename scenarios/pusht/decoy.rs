//! Decoy pushing: the expert's skilled pushes, aimed at random poses instead of the goal.
//!
//! Why: in expert demonstrations the block only ever moves towards the goal, so a
//! world model trained on them learns "a pushed block slides onto the goal" and
//! imagines success for policies that push badly. Decoy episodes show the same
//! contact dynamics with the block pushed anywhere: the expert's planner gets a
//! decoy pose drawn from the block's reset distribution (uniform position in
//! `reset.block_range`, uniform orientation) and a new one every
//! [`DECOY_PERIOD`] control steps, or sooner once the block is there. The frames
//! still show the episode's real goal.

use std::f64::consts::PI;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::PushTEnv;
use super::expert::{Expert, pose_error};
use super::geometry::Pose2;

/// Control steps between two decoy poses.
pub const DECOY_PERIOD: u32 = 75;
/// Pose error (world units, see [`pose_error`]) at which a decoy counts as reached.
const REACHED: f64 = 20.0;

/// The expert pushing towards seeded random poses.
pub struct Decoy {
    expert: Expert,
    rng: ChaCha8Rng,
    target: Option<Pose2>,
    since: u32,
}

impl Decoy {
    /// Wraps `expert`; the decoy poses come only from `seed`.
    pub fn new(expert: Expert, seed: u64) -> Self {
        Self { expert, rng: ChaCha8Rng::seed_from_u64(seed), target: None, since: 0 }
    }

    /// The decoy pose the expert is pushing to (none before the first action).
    pub fn target(&self) -> Option<Pose2> {
        self.target
    }

    fn draw(&mut self, env: &PushTEnv) -> Pose2 {
        let r = env.config().reset.block_range;
        let x = self.rng.random_range(r[0]..r[1]);
        let y = self.rng.random_range(r[0]..r[1]);
        Pose2::new(x, y, self.rng.random_range(-PI..PI))
    }

    /// The next action (the agent's absolute target position).
    pub fn act(&mut self, env: &PushTEnv) -> [f64; 2] {
        let reached = self.target.is_some_and(|t| pose_error(&env.state().block, &t) < REACHED);
        if self.target.is_none() || self.since >= DECOY_PERIOD || reached {
            let t = self.draw(env);
            self.target = Some(t);
            self.expert.set_target(Some(t));
            self.since = 0;
        }
        self.since += 1;
        self.expert.act(env)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pusht::{PushTConfig, PushTPhysics};

    fn env(seed: u64) -> PushTEnv {
        let cfg = PushTConfig::default();
        let model = PushTPhysics::compile(&cfg).expect("model compiles");
        let mut env = PushTEnv::new(model, &cfg);
        env.reset(seed).expect("reset");
        env
    }

    #[test]
    fn decoys_are_seeded_and_inside_the_block_range() {
        let e = env(3);
        let (mut a, mut b, mut c) = (
            Decoy::new(Expert::new(e.model(), e.config()), 7),
            Decoy::new(Expert::new(e.model(), e.config()), 7),
            Decoy::new(Expert::new(e.model(), e.config()), 8),
        );
        let (ta, tb, tc) = (a.draw(&e), b.draw(&e), c.draw(&e));
        assert_eq!(ta, tb);
        assert_ne!(ta, tc);
        let r = e.config().reset.block_range;
        for t in [ta, tc] {
            assert!((r[0]..r[1]).contains(&t.x) && (r[0]..r[1]).contains(&t.y), "{t:?}");
            assert!((-PI..PI).contains(&t.theta));
        }
    }

    #[test]
    fn the_block_is_pushed_towards_the_decoy_not_the_goal() {
        // Over one decoy period the expert's pushes cut the block's pose error to the
        // decoy; the decoy is random, so the goal is not what the block approaches.
        let mut e = env(5);
        let mut d = Decoy::new(Expert::new(e.model(), e.config()), 11);
        let first = d.act(&e);
        let target = d.target().expect("a decoy after the first action");
        let before = pose_error(&e.state().block, &target);
        e.step(first).expect("step");
        for _ in 1..DECOY_PERIOD - 1 {
            let a = d.act(&e);
            e.step(a).expect("step");
            if d.target() != Some(target) {
                break; // reached early and redrawn
            }
        }
        let after = pose_error(&e.state().block, &target);
        assert!(after < 0.7 * before, "pose error to the decoy {before:.1} -> {after:.1}");
    }
}
