//! numpy's legacy `RandomState` (MT19937), so that a Push-T reset can draw exactly what GPC's
//! does (`np.random.RandomState(seed)`, then `uniform` and `randn` in its order).
//!
//! Three pieces of numpy's legacy generator, written from their published definitions:
//! - seeding with a 32-bit integer: Matsumoto and Nishimura's `init_genrand` (numpy's
//!   `mt19937_seed`), 624 words of state;
//! - `random_sample`: a 53-bit double from two tempered 32-bit outputs,
//!   `((a >> 5)·2^26 + (b >> 6)) / 2^53`; `uniform(lo, hi)` is `lo + (hi − lo)·random_sample()`;
//! - `randn`: the polar Box–Muller method, which yields two normals per accepted pair and keeps
//!   the second for the next call.

use super::config::PushTConfig;
use super::physics::PushTState;
use super::{MAX_RESET_DRAWS, Pose2};
use crate::error::ScenarioError;

/// GPC's reset of episode `seed`: `RandomState(seed)`; agent x, y ~ U(agent_range); block
/// x, y ~ U(block_range), θ = randn·2π − π; goal x, y ~ U(goal_range), θ likewise (unless
/// `fixed_goal`); then the agent is redrawn while closer than `min_agent_block_distance` to
/// the block's centre. Angles are not wrapped, as GPC leaves them.
///
/// # Errors
/// [`ScenarioError::ImpossibleReset`] for a seed of 2^32 or more (numpy refuses it) or when
/// the agent never clears the block.
pub fn gpc_initial_state(cfg: &PushTConfig, seed: u64) -> Result<(PushTState, Pose2), ScenarioError> {
    let Ok(s) = u32::try_from(seed) else {
        return Err(ScenarioError::ImpossibleReset {
            seed,
            draws: 0,
            field: "reset.rng (seeds below 2^32)".into(),
        });
    };
    let mut rs = RandomState::new(s);
    let r = &cfg.reset;
    let tau = std::f64::consts::TAU;
    let pi = std::f64::consts::PI;
    let mut agent =
        [rs.uniform(r.agent_range[0], r.agent_range[1]), rs.uniform(r.agent_range[0], r.agent_range[1])];
    let bx = rs.uniform(r.block_range[0], r.block_range[1]);
    let by = rs.uniform(r.block_range[0], r.block_range[1]);
    let block = Pose2::new(bx, by, rs.randn() * tau - pi);
    let gx = rs.uniform(r.goal_range[0], r.goal_range[1]);
    let gy = rs.uniform(r.goal_range[0], r.goal_range[1]);
    let mut goal = Pose2::new(gx, gy, rs.randn() * tau - pi);
    if r.fixed_goal {
        goal = cfg.fixed_goal();
    }
    let mut draws = 1;
    while (agent[0] - block.x).hypot(agent[1] - block.y) < r.min_agent_block_distance {
        if draws == MAX_RESET_DRAWS {
            return Err(ScenarioError::ImpossibleReset {
                seed,
                draws,
                field: "reset.min_agent_block_distance".into(),
            });
        }
        agent =
            [rs.uniform(r.agent_range[0], r.agent_range[1]), rs.uniform(r.agent_range[0], r.agent_range[1])];
        draws += 1;
    }
    Ok((PushTState { agent, agent_vel: [0.0; 2], block }, goal))
}

/// Words of MT19937 state.
const N: usize = 624;
const M: usize = 397;

/// numpy's `RandomState(seed)` for a seed in 0..2^32.
#[derive(Clone, Debug)]
pub struct RandomState {
    mt: [u32; N],
    pos: usize,
    /// The second normal of the last polar pair, not yet handed out.
    gauss: Option<f64>,
}

impl RandomState {
    /// Seeded as `np.random.RandomState(seed)`.
    pub fn new(seed: u32) -> Self {
        let mut mt = [0u32; N];
        mt[0] = seed;
        for i in 1..N {
            mt[i] = 1_812_433_253u32.wrapping_mul(mt[i - 1] ^ (mt[i - 1] >> 30)).wrapping_add(i as u32);
        }
        Self { mt, pos: N, gauss: None }
    }

    /// The next tempered 32-bit output.
    pub fn next_u32(&mut self) -> u32 {
        if self.pos >= N {
            self.refill();
        }
        let mut y = self.mt[self.pos];
        self.pos += 1;
        y ^= y >> 11;
        y ^= (y << 7) & 0x9d2c_5680;
        y ^= (y << 15) & 0xefc6_0000;
        y ^ (y >> 18)
    }

    fn refill(&mut self) {
        const UPPER: u32 = 0x8000_0000;
        const LOWER: u32 = 0x7fff_ffff;
        let twist = |y: u32| (y >> 1) ^ if y & 1 == 1 { 0x9908_b0df } else { 0 };
        for i in 0..N {
            let y = (self.mt[i] & UPPER) | (self.mt[(i + 1) % N] & LOWER);
            self.mt[i] = self.mt[(i + M) % N] ^ twist(y);
        }
        self.pos = 0;
    }

    /// `random_sample()`: uniform in [0, 1) with 53 random bits.
    pub fn random_sample(&mut self) -> f64 {
        let a = f64::from(self.next_u32() >> 5);
        let b = f64::from(self.next_u32() >> 6);
        (a * 67_108_864.0 + b) / 9_007_199_254_740_992.0
    }

    /// `uniform(lo, hi)`.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.random_sample()
    }

    /// `randn()`: a standard normal.
    pub fn randn(&mut self) -> f64 {
        if let Some(g) = self.gauss.take() {
            return g;
        }
        loop {
            let x1 = 2.0 * self.random_sample() - 1.0;
            let x2 = 2.0 * self.random_sample() - 1.0;
            let r2 = x1 * x1 + x2 * x2;
            if r2 < 1.0 && r2 != 0.0 {
                let f = (-2.0 * r2.ln() / r2).sqrt();
                self.gauss = Some(f * x1);
                return f * x2;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_outputs_are_the_reference_generators() {
        // MT19937 seeded with init_genrand(5489), the reference implementation's default:
        // its first output is 3499211612 (Matsumoto and Nishimura's mt19937ar.c test vector).
        let mut r = RandomState::new(5489);
        assert_eq!(r.next_u32(), 3_499_211_612);
        // numpy 2.4.6, `np.random.RandomState(0)`: random_sample() = 0.5488135039273248 and
        // randn() after it 0.7415917408091613; RandomState(0).randn(2) =
        // [1.764052345967664, 0.4001572083672233] (the second is the pair's cached value).
        let mut r = RandomState::new(0);
        assert_eq!([r.random_sample(), r.randn()], [0.548_813_503_927_324_8, 0.741_591_740_809_161_3]);
        let mut r = RandomState::new(0);
        assert_eq!([r.randn(), r.randn()], [1.764_052_345_967_664, 0.400_157_208_367_223_3]);
    }
}

#[cfg(test)]
mod gpc_tests {
    use super::*;

    #[test]
    fn seeds_reproduce_gpc_s_initial_states() {
        // scenarios/pusht/gpc_resets.tsv: numpy's own draws in GPC's order for seeds
        // 100000-100099 (scripts/fixtures/gpc_resets.py).
        let mut cfg = PushTConfig::default();
        cfg.reset.rng = super::super::config::ResetRng::GpcNumpy;
        let table = include_str!("gpc_resets.tsv");
        let mut rows = 0;
        for line in table.lines().skip(1) {
            let v: Vec<f64> = line.split('\t').map(|x| x.parse().unwrap_or(f64::NAN)).collect();
            let (s, goal) = gpc_initial_state(&cfg, v[0] as u64).unwrap_or_else(|e| panic!("{e}"));
            let got =
                [s.agent[0], s.agent[1], s.block.x, s.block.y, s.block.theta, goal.x, goal.y, goal.theta];
            for (g, w) in got.iter().zip(&v[1..]) {
                assert!((g - w).abs() <= 1e-9, "seed {}: {got:?} vs {:?}", v[0], &v[1..]);
            }
            // `initial_state` takes this path for the setting.
            assert_eq!(super::super::initial_state(&cfg, v[0] as u64).ok(), Some((s, goal)));
            rows += 1;
        }
        assert_eq!(rows, 100);
        let e = gpc_initial_state(&cfg, 1 << 32).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(e.contains("reset.rng"), "{e}");
    }
}
