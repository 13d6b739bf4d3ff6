//! Exploration around a scripted behaviour: calm stretches, in which the
//! behaviour reaches its waypoints, between disturbances, in which a smooth
//! random drift is added to the arm's six action entries or alone drives them.
//!
//! Why: a world model trained on the scripted behaviours alone sees actions that
//! are predictable from the frames (every behaviour heads for the object), so it
//! can learn the usual trajectory and ignore the actions. Learned policies that
//! fail do something else: their wrists twist and they wander off. The
//! `explore` behaviour covers those actions (translations, large rotations,
//! gripper commands at odd times) near the object, where they matter. The
//! random stream derives from the episode's seed, so an episode stays a pure
//! function of its seed.

use harness::seed::{derive, fnv1a};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Correlation time of the drift, in control steps (20 Hz: about 0.75 s).
pub const DRIFT_STEPS: f64 = 15.0;
/// The range of the drift's stationary standard deviation, drawn once per episode
/// (action units: 1 is the controller's full-scale command).
pub const DRIFT_STD: (f64, f64) = (0.3, 1.0);
/// Chance per calm step that a disturbance begins.
pub const DISTURB_RATE: f64 = 0.04;
/// The range of a disturbance's length, in steps.
pub const DISTURB_STEPS: (usize, usize) = (10, 40);

/// What the current stretch of steps does to the behaviour's action.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Stretch {
    /// The behaviour's action unchanged, so that it can reach its waypoints.
    Calm,
    /// The drift added to the behaviour's arm entries.
    Drift,
    /// The drift alone drives the arm, with this gripper command held.
    Lapse(f64),
}

/// The drift and disturbances of one episode.
pub struct Wander {
    rng: ChaCha8Rng,
    std: f64,
    drift: [f64; 6],
    stretch: Stretch,
    /// Steps left in the current disturbance.
    left: usize,
}

impl Wander {
    /// Episode `seed`'s exploration in `scenario`.
    pub fn new(scenario: &str, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(derive(seed, &[fnv1a(scenario), fnv1a("wander")]));
        let std = rng.random_range(DRIFT_STD.0..=DRIFT_STD.1);
        Self { rng, std, drift: [0.0; 6], stretch: Stretch::Calm, left: 0 }
    }

    /// This episode's drift standard deviation.
    pub fn std(&self) -> f64 {
        self.std
    }

    /// The action to apply instead of the behaviour's `guided` one.
    ///
    /// Each drift entry is an Ornstein–Uhlenbeck process, `x ← ρx + √(1−ρ²)·σ·ε`
    /// with ρ = exp(−1/`DRIFT_STEPS`), so its stationary std is σ; it runs every
    /// step. Calm steps pass `guided` through. A calm step starts a disturbance
    /// with chance `DISTURB_RATE`, half of them drifts (the drift added to the arm
    /// entries) and half lapses (the drift alone, with a full gripper command drawn
    /// at the start and held); calm returns when it ends.
    pub fn apply(&mut self, guided: [f64; 7]) -> [f64; 7] {
        let rho = (-1.0 / DRIFT_STEPS).exp();
        let kick = (1.0 - rho * rho).sqrt() * self.std;
        for d in &mut self.drift {
            let e: f64 = self.rng.sample(StandardNormal);
            *d = rho * *d + kick * e;
        }
        if self.stretch == Stretch::Calm && self.rng.random_bool(DISTURB_RATE) {
            self.left = self.rng.random_range(DISTURB_STEPS.0..=DISTURB_STEPS.1);
            self.stretch = if self.rng.random_bool(0.5) {
                Stretch::Drift
            } else {
                Stretch::Lapse(if self.rng.random_bool(0.5) { 1.0 } else { -1.0 })
            };
        }
        let mut a = guided;
        match self.stretch {
            Stretch::Calm => return a,
            Stretch::Drift => {
                for (v, d) in a.iter_mut().zip(self.drift) {
                    *v = (*v + d).clamp(-1.0, 1.0);
                }
            }
            Stretch::Lapse(grip) => {
                for (v, d) in a.iter_mut().zip(self.drift) {
                    *v = d.clamp(-1.0, 1.0);
                }
                a[6] = grip;
            }
        }
        self.left -= 1;
        if self.left == 0 {
            self.stretch = Stretch::Calm;
        }
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_drift_is_a_pure_function_of_the_seed() {
        let run = |seed| {
            let mut w = Wander::new("lift", seed);
            (0..50).map(|_| w.apply([0.0; 7])).collect::<Vec<_>>()
        };
        assert_eq!(run(3), run(3));
        assert_ne!(run(3), run(4));
    }

    #[test]
    fn disturbances_come_and_go_and_stay_in_range() {
        // With a zero guided action a calm step is exactly zero, a disturbed one the
        // drift (clamped to [−1, 1]). A calm run lasts 1 / 0.04 = 25 steps on average
        // and a disturbance 25 (10..=40), so about half of 4,000 steps are disturbed.
        let mut w = Wander::new("lift", 11);
        assert!((DRIFT_STD.0..=DRIFT_STD.1).contains(&w.std()));
        let xs: Vec<[f64; 7]> = (0..4000).map(|_| w.apply([0.0; 7])).collect();
        assert!(xs.iter().flatten().all(|x| x.abs() <= 1.0));
        let disturbed = xs.iter().filter(|a| a[..6].iter().any(|v| *v != 0.0)).count();
        assert!((1200..2800).contains(&disturbed), "{disturbed} disturbed steps");
        // Neighbouring disturbed steps are strongly correlated (ρ = e^(−1/15) ≈ 0.936).
        let pairs: Vec<(f64, f64)> =
            xs.windows(2).filter(|p| p[0][0] != 0.0 && p[1][0] != 0.0).map(|p| (p[0][0], p[1][0])).collect();
        let (sxy, sxx) = pairs.iter().fold((0.0, 0.0), |(a, b), (x, y)| (a + x * y, b + x * x));
        assert!(sxy / sxx > 0.8, "lag-1 correlation {}", sxy / sxx);
    }

    #[test]
    fn lapses_hold_a_full_gripper_command_and_end() {
        // A guided gripper command of 0.25 is never a lapse's (±1), so the steps that
        // show ±1 are lapses: about a quarter of 2,000 steps (half the disturbed
        // half), and the guided command returns after each.
        let mut w = Wander::new("lift", 5);
        let grips: Vec<f64> = (0..2000).map(|_| w.apply([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.25])[6]).collect();
        let lapsed = grips.iter().filter(|g| g.abs() == 1.0).count();
        assert!(lapsed > 150 && lapsed < 1000, "{lapsed} lapsed steps");
        assert!(grips.iter().all(|g| *g == 0.25 || g.abs() == 1.0));
    }
}
