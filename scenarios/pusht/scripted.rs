//! The `scripted` policy kind: the Push-T expert acting from what a learned
//! policy sees, with configurable action noise and lag.
//!
//! A learned policy gets two frames and the agent position, never the simulator
//! state; so does this one. Each decision it reads the block and goal poses from
//! the newest frame ([`super::perceive`]), takes the agent position and velocity
//! from the two positions, and lets the expert ([`super::expert`]) plan an
//! action chunk by acting in a private simulator set to that estimated state.
//! Then, per decision:
//!
//! - **lag** k: the first k actions of the chunk hold the agent where it is and
//!   the plan's first `H − k` actions follow (a reaction delay of k steps);
//! - **noise** σ: every coordinate gets N(0, σ²) world units from the episode's
//!   own noise stream, then is clipped to the world.
//!
//! Quality is therefore controllable (σ = 0..100, lag 0..4 spans nearly perfect to
//! poor), which makes graded policy sets for tests and quick studies without
//! training. In the world-model branch of `rank` the frames are imagined, so the
//! expert reads the imagined block and goal — a check of the world model that does
//! not depend on how well a policy was trained. A frame without a visible block
//! makes the policy hold still.
//!
//! `policy.json`: `{"kind": "scripted", "config": {"noise": σ, "lag": k,
//! "action_horizon": H}, "provenance": {...}}`.

use std::path::Path;
use std::sync::Arc;

use harness::policy::{ActionChunk, Observation, Policy, PolicyError};
use harness::rng::Rng;
use mujoco_rs::prelude::MjModel;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::expert::Expert;
use super::perceive::Perceiver;
use super::physics::PushTState;
use super::{PushTConfig, PushTEnv};
use crate::error::ScenarioError;

/// The kind's configuration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScriptedConfig {
    /// Standard deviation of the action noise (world units).
    #[serde(default)]
    pub noise: f64,
    /// Control steps each decision starts by holding still.
    #[serde(default)]
    pub lag: usize,
    /// Actions per decision.
    #[serde(default = "default_horizon")]
    pub action_horizon: usize,
}

fn default_horizon() -> usize {
    8
}

/// `policy.json` of a scripted checkpoint.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScriptedFile {
    /// Always `scripted`.
    pub kind: String,
    /// Noise, lag, horizon.
    pub config: ScriptedConfig,
    /// How it was made.
    #[serde(default)]
    pub provenance: serde_json::Value,
}

/// The expert, acting from frames.
pub struct ScriptedPolicy {
    name: String,
    cfg: ScriptedConfig,
    scenario: PushTConfig,
    model: Arc<MjModel>,
    perceiver: Perceiver,
    size: usize,
}

impl ScriptedPolicy {
    /// A policy named `name` for frames of `size` pixels.
    ///
    /// # Errors
    /// [`ScenarioError::InvalidField`] (naming `policy.json`) when the configuration is
    /// unusable: negative or non-finite noise, a lag that leaves no action, a zero horizon.
    pub fn new(
        name: &str,
        cfg: ScriptedConfig,
        scenario: &PushTConfig,
        model: Arc<MjModel>,
        size: usize,
    ) -> Result<Self, ScenarioError> {
        let bad = |field: &str, reason: String| ScenarioError::InvalidField {
            path: "policy.json".into(),
            field: format!("config.{field}"),
            reason,
        };
        if !(cfg.noise.is_finite() && cfg.noise >= 0.0) {
            return Err(bad("noise", format!("must be a finite number >= 0, got {}", cfg.noise)));
        }
        if cfg.action_horizon == 0 || cfg.lag >= cfg.action_horizon {
            return Err(bad(
                "lag",
                format!(
                    "{} must be below \"action_horizon\" ({}), which must be positive",
                    cfg.lag, cfg.action_horizon
                ),
            ));
        }
        let perceiver = Perceiver::new(scenario, size);
        Ok(Self { name: name.into(), cfg, scenario: scenario.clone(), model, perceiver, size })
    }

    /// Loads `dir/policy.json` (kind `scripted`); the policy is named after `dir`.
    ///
    /// # Errors
    /// [`ScenarioError`] naming the file: [`ScenarioError::Io`] unreadable,
    /// [`ScenarioError::Parse`] not JSON of a scripted policy, [`ScenarioError::InvalidField`]
    /// another kind or a bad config.
    pub fn load(
        dir: &Path,
        scenario: &PushTConfig,
        model: Arc<MjModel>,
        size: usize,
    ) -> Result<Self, ScenarioError> {
        let path = dir.join("policy.json");
        let text = std::fs::read_to_string(&path)
            .map_err(|source| ScenarioError::Io { path: path.clone(), source })?;
        let file: ScriptedFile = serde_json::from_str(&text)
            .map_err(|e| ScenarioError::Parse { path: path.clone(), message: e.to_string() })?;
        if file.kind != "scripted" {
            return Err(ScenarioError::InvalidField {
                path,
                field: "kind".into(),
                reason: format!("\"{}\" is not \"scripted\"", file.kind),
            });
        }
        let name =
            dir.file_name().map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into_owned());
        Self::new(&name, file.config, scenario, model, size).map_err(|e| match e {
            ScenarioError::InvalidField { field, reason, .. } => {
                ScenarioError::InvalidField { path, field, reason }
            }
            other => other,
        })
    }

    /// The expert's plan for one observation (before lag and noise).
    fn plan(&self, o: &Observation) -> Vec<[f32; 2]> {
        let h = self.cfg.action_horizon;
        let last = o.proprio.last().map_or([0.0; 2], |p| [f64::from(p[0]), f64::from(p[1])]);
        let hold = vec![[last[0] as f32, last[1] as f32]; h];
        let Some(seen) = o.frames.last().and_then(|f| self.perceiver.perceive(f, Some(last))) else {
            return hold;
        };
        // The PD law's velocity, from the last two positions one control step apart.
        let hz = f64::from(self.scenario.timing.control_hz);
        let vel = match o.proprio.len() {
            n if n >= 2 => {
                let p = &o.proprio[n - 2];
                [(last[0] - f64::from(p[0])) * hz, (last[1] - f64::from(p[1])) * hz]
            }
            _ => [0.0; 2],
        };
        let mut env = PushTEnv::new(self.model.clone(), &self.scenario);
        env.set_state(&PushTState { agent: last, agent_vel: vel, block: seen.block });
        env.set_goal(seen.goal);
        let mut expert = Expert::new(self.model.clone(), &self.scenario);
        let mut chunk = Vec::with_capacity(h);
        for _ in 0..h {
            let a = expert.act(&env);
            chunk.push([a[0] as f32, a[1] as f32]);
            if env.step(a).is_err() {
                // The imagined state diverged (a misread pose overlapping the agent):
                // repeat the last action for the rest of the chunk.
                chunk.resize(h, [a[0] as f32, a[1] as f32]);
                break;
            }
        }
        chunk
    }
}

impl Policy for ScriptedPolicy {
    fn name(&self) -> &str {
        &self.name
    }

    fn obs_horizon(&self) -> usize {
        2
    }

    fn action_horizon(&self) -> usize {
        self.cfg.action_horizon
    }

    fn act(&self, obs: &[Observation], rngs: &mut [Rng]) -> Result<Vec<ActionChunk>, PolicyError> {
        if rngs.len() != obs.len() {
            let message = format!("{} observations but {} noise streams", obs.len(), rngs.len());
            return Err(PolicyError::Input { policy: self.name.clone(), message });
        }
        if let Some(o) = obs
            .iter()
            .find(|o| o.size != self.size || o.frames.iter().any(|f| f.len() != o.size * o.size * 3))
        {
            let message = format!("takes {0}x{0} RGB frames, got {1}x{1}", self.size, o.size);
            return Err(PolicyError::Input { policy: self.name.clone(), message });
        }
        if let Some(v) = obs.iter().flat_map(|o| &o.proprio).find(|v| v.len() != 2) {
            let message = format!("reads the agent's 2-D position, got {} proprioceptive entries", v.len());
            return Err(PolicyError::Input { policy: self.name.clone(), message });
        }
        // Planning is deterministic per episode; the noise is drawn afterwards, in
        // episode order, from each episode's own stream.
        let plans: Vec<Vec<[f32; 2]>> = obs.par_iter().map(|o| self.plan(o)).collect();
        let world = self.scenario.world.size as f32;
        let out = plans
            .into_iter()
            .zip(obs)
            .zip(rngs.iter_mut())
            .map(|((plan, o), rng)| {
                let here = o.proprio.last().cloned().unwrap_or_else(|| vec![0.0; 2]);
                let lag = self.cfg.lag;
                let mut chunk: ActionChunk = std::iter::repeat_n(here, lag)
                    .chain(plan.into_iter().take(self.cfg.action_horizon - lag).map(Vec::from))
                    .collect();
                if self.cfg.noise > 0.0 {
                    for a in &mut chunk {
                        for v in a.iter_mut() {
                            *v = (*v + (rng.normal() * self.cfg.noise) as f32).clamp(0.0, world);
                        }
                    }
                }
                chunk
            })
            .collect();
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pusht::initial_state;
    use crate::pusht::physics::PushTPhysics;
    use crate::pusht::render::Rasterizer;

    fn setup() -> (PushTConfig, Arc<MjModel>) {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("pusht.toml");
        let cfg = PushTConfig::from_file(&path).unwrap();
        let model = PushTPhysics::compile(&cfg).unwrap();
        (cfg, model)
    }

    fn observe(cfg: &PushTConfig, seed: u64) -> Observation {
        let (state, goal) = initial_state(cfg, seed).unwrap();
        let frame = Rasterizer::new(cfg).render(&state, &goal);
        let p = vec![state.agent[0] as f32, state.agent[1] as f32];
        Observation {
            frames: vec![frame.clone(), frame],
            proprio: vec![p.clone(), p],
            robot: vec![Vec::new(); 2],
            size: 96,
            exact: None,
            native: None,
        }
    }

    #[test]
    fn the_noiseless_policy_replays_the_expert_on_the_true_state() {
        let (cfg, model) = setup();
        let policy = ScriptedPolicy::new(
            "s",
            ScriptedConfig { noise: 0.0, lag: 0, action_horizon: 8 },
            &cfg,
            model.clone(),
            96,
        )
        .unwrap();
        let obs = observe(&cfg, 3);
        let chunk = policy.act(std::slice::from_ref(&obs), &mut [Rng::new(1)]).unwrap().remove(0);
        // The expert on the exact state, stepped in its own environment.
        let mut env = PushTEnv::new(model.clone(), &cfg);
        env.reset(3).unwrap();
        let mut expert = Expert::new(model, &cfg);
        let first = expert.act(&env);
        assert_eq!(chunk.len(), 8);
        // The perceived block is within a few units, so the first target agrees closely.
        let d = (f64::from(chunk[0][0]) - first[0]).hypot(f64::from(chunk[0][1]) - first[1]);
        assert!(d < 15.0, "first action {:?} vs the expert's {first:?}", chunk[0]);
    }

    #[test]
    fn lag_holds_then_follows_and_noise_is_seeded_per_episode() {
        let (cfg, model) = setup();
        let make = |noise, lag| {
            ScriptedPolicy::new(
                "s",
                ScriptedConfig { noise, lag, action_horizon: 8 },
                &cfg,
                model.clone(),
                96,
            )
            .unwrap()
        };
        let obs = vec![observe(&cfg, 5), observe(&cfg, 6)];
        let clean = make(0.0, 0).act(&obs, &mut [Rng::new(1), Rng::new(2)]).unwrap();
        let lagged = make(0.0, 3).act(&obs, &mut [Rng::new(1), Rng::new(2)]).unwrap();
        for (c, l) in clean.iter().zip(&lagged) {
            assert_eq!(&l[3..], &c[..5]);
        }
        assert!(lagged[0][..3].iter().all(|a| *a == obs[0].proprio[1]));
        let noisy = make(20.0, 0);
        let a = noisy.act(&obs, &mut [Rng::new(1), Rng::new(2)]).unwrap();
        // Episode 1's noise depends on its own stream only, not on its batch mates.
        let b = noisy.act(&obs[1..], &mut [Rng::new(2)]).unwrap();
        assert_eq!(a[1], b[0]);
        assert_ne!(a[0], clean[0]);
    }

    #[test]
    fn bad_configs_and_frames_are_errors() {
        let (cfg, model) = setup();
        let bad = ScriptedConfig { noise: 0.0, lag: 8, action_horizon: 8 };
        assert!(ScriptedPolicy::new("s", bad, &cfg, model.clone(), 96).is_err());
        let nan = ScriptedConfig { noise: f64::NAN, lag: 0, action_horizon: 8 };
        assert!(ScriptedPolicy::new("s", nan, &cfg, model.clone(), 96).is_err());
        let p = ScriptedPolicy::new(
            "s",
            ScriptedConfig { noise: 0.0, lag: 0, action_horizon: 8 },
            &cfg,
            model,
            96,
        )
        .unwrap();
        let mut o = observe(&cfg, 1);
        o.size = 64;
        let e = p.act(&[o], &mut [Rng::new(0)]).unwrap_err();
        assert!(e.to_string().contains("takes 96x96"), "{e}");
    }
}
