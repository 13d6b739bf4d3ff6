//! Random exploration: smooth random targets that often touch the block.
//!
//! Datasets for world models need bad and aimless behaviour as well as expert
//! pushes (the GPC / DriftWorld Push-T data mixes both). The explorer walks its
//! target towards random waypoints at a random speed; half of the waypoints
//! are drawn around the block so that the data has plenty of contact.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::PushTEnv;

/// A smooth random-target behaviour with its own seeded RNG.
pub struct Explorer {
    rng: ChaCha8Rng,
    target: Option<[f64; 2]>,
    waypoint: [f64; 2],
    speed: f64,
}

impl Explorer {
    /// An explorer whose randomness comes only from `seed`.
    pub fn new(seed: u64) -> Self {
        Self { rng: ChaCha8Rng::seed_from_u64(seed), target: None, waypoint: [0.0; 2], speed: 0.0 }
    }

    fn new_waypoint(&mut self, env: &PushTEnv) {
        let size = env.config().world.size;
        let lo = 30.0;
        let hi = size - 30.0;
        let block = env.state().block;
        self.waypoint = if self.rng.random_bool(0.5) {
            let n = Normal::new(0.0, 70.0).unwrap_or_else(|_| unreachable!("σ = 70 is valid"));
            [
                (block.x + n.sample(&mut self.rng)).clamp(lo, hi),
                (block.y + n.sample(&mut self.rng)).clamp(lo, hi),
            ]
        } else {
            [self.rng.random_range(lo..hi), self.rng.random_range(lo..hi)]
        };
        // World units per control step (0.1 s): 8-35, i.e. 80-350 units/s.
        self.speed = self.rng.random_range(8.0..35.0);
    }

    /// The next action (absolute target position).
    pub fn act(&mut self, env: &PushTEnv) -> [f64; 2] {
        let target = match self.target {
            Some(t) => t,
            None => {
                self.new_waypoint(env);
                env.state().agent
            }
        };
        let (dx, dy) = (self.waypoint[0] - target[0], self.waypoint[1] - target[1]);
        let dist = dx.hypot(dy);
        let next = if dist <= self.speed {
            let reached = self.waypoint;
            self.new_waypoint(env);
            reached
        } else {
            [target[0] + dx / dist * self.speed, target[1] + dy / dist * self.speed]
        };
        self.target = Some(next);
        next
    }
}
