//! One simulator for robosuite's manipulation tasks. A task is an [`ArmScene`]: how its scene is
//! composed, where its object is placed at reset, when it has succeeded, its state columns and
//! its scripted behaviours (an expert with flaws, uniform random actions, or the expert with a
//! wandering drift). [`ArmSim`] and [`SceneEpisode`] do the rest once for every such task: the
//! seeded reset, the episode with the recipe a render worker builds its model from, a scripted
//! episode run under its perturbation, and the interfaces of the data commands
//! ([`super::runs`], [`super::datasets`]) and of the engine ([`super::task`]).
//!
//! `lift/` and `can/` keep only what differs: their configs, scene XML, placement, success
//! check and experts.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use harness::seed::{derive, fnv1a};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use mujoco_rs::prelude::MjModel;

use super::episode::{ArmEpisode, ObjectNames};
use super::render_pool::ModelKey;
use super::rollout::{Episode, Perturbation, RandomActions, Recorded, Row, RunLimits};
use super::wander::Wander;
use crate::error::ScenarioError;

/// A scripted behaviour's actions from the episode's current state.
pub type Actor<'a> = Box<dyn FnMut(&ArmEpisode) -> [f64; 7] + 'a>;

/// What a robosuite task is: the parts of its simulator that differ from the other tasks'.
pub trait ArmScene: Send + Sync + Sized + 'static {
    /// Its parameters (robosuite's defaults, or a scenario file's), recorded with every run
    /// and dataset, and the recipe a render worker rebuilds the model from.
    type Config: serde::Serialize + Send + Sync;
    /// An episode's initial state, a pure function of the config and the seed.
    type Init: Copy + serde::Serialize + Send + Sync + 'static;
    /// Its scripted behaviours.
    type Behaviour: Copy + Send + Sync + PartialEq + 'static;
    /// The task's name (`lift`, `can`).
    const NAME: &'static str;
    /// The state row's column names (the object's pose, then [`super::episode::ROBOT_COLUMNS`]).
    const STATE_COLUMNS: &'static [&'static str];
    /// The object's body and free joint in the composed scene.
    const OBJECT: ObjectNames<'static>;

    /// The config.
    fn config(&self) -> &Self::Config;
    /// The default step limit.
    fn max_steps(&self) -> usize;
    /// The side the camera renders at before frames are resized, when not the frames' own.
    fn render_size(&self) -> Option<u32>;
    /// Places episode `seed`: the arm's joint noise and the object's pose, in robosuite's
    /// order of draws.
    fn place(&self, seed: u64) -> Self::Init;
    /// The arm's joints of an initial state.
    fn arm_q(init: &Self::Init) -> [f64; 7];
    /// The object's pose of an initial state: x, y, z, qw, qx, qy, qz.
    fn object_pose(init: &Self::Init) -> [f64; 7];
    /// The object's half-sizes when they are drawn per episode (Lift's cube), which a render
    /// worker needs to build the same model.
    fn object_half(init: &Self::Init) -> Option<[f64; 3]>;
    /// Composes the scene an episode from `init` runs in, from the assets in `dir`.
    ///
    /// # Errors
    /// Missing assets or a model MuJoCo refuses.
    fn compose(&self, dir: &Path, init: &Self::Init) -> Result<MjModel, ScenarioError>;
    /// robosuite's success check on the episode's current state.
    fn success(&self, arm: &ArmEpisode) -> bool;
    /// The behaviours by name, the expert first.
    fn behaviours(&self) -> &'static [(&'static str, Self::Behaviour)];
    /// The actions of `behaviour`: its scripted actor, or `None` for uniform random actions
    /// ([`RandomActions`]).
    fn actor(&self, behaviour: Self::Behaviour) -> Option<Actor<'_>>;
    /// Whether `behaviour` adds the wandering drift ([`Wander`]) to its actor's actions.
    fn wanders(behaviour: Self::Behaviour) -> bool;
}

/// A robosuite task's simulator: its scene and the asset folder.
pub struct ArmSim<S> {
    scene: Arc<S>,
    dir: PathBuf,
}

impl<S: ArmScene> ArmSim<S> {
    /// The simulator of `scene`, whose assets are in `dir`.
    pub fn of(scene: S, dir: PathBuf) -> Self {
        Self { scene: Arc::new(scene), dir }
    }

    /// The scene.
    pub fn scene(&self) -> &S {
        &self.scene
    }

    /// The config.
    pub fn config(&self) -> &S::Config {
        self.scene.config()
    }

    /// The task's name.
    pub fn name(&self) -> &'static str {
        S::NAME
    }

    /// The state row's column names.
    pub fn state_columns(&self) -> Vec<&'static str> {
        S::STATE_COLUMNS.to_vec()
    }

    /// The default step limit.
    pub fn max_steps(&self) -> usize {
        self.scene.max_steps()
    }

    /// The config, for `config.json` and the dataset's attributes.
    pub fn config_json(&self) -> serde_json::Value {
        serde_json::to_value(self.config()).unwrap_or_default()
    }

    /// The behaviours by name, the expert first.
    pub fn behaviours(&self) -> &'static [(&'static str, S::Behaviour)] {
        self.scene.behaviours()
    }

    /// A behaviour's name.
    pub fn behaviour_name(&self, b: S::Behaviour) -> &'static str {
        self.behaviours().iter().find(|(_, k)| *k == b).map_or("?", |(n, _)| n)
    }

    /// Episode `seed` at its initial state.
    ///
    /// # Errors
    /// A model MuJoCo refuses.
    pub fn reset(&self, seed: u64) -> Result<SceneEpisode<S>, ScenarioError> {
        self.reset_to(seed, self.scene.place(seed))
    }

    /// An episode from a given initial state (the cross-check with robosuite starts both
    /// simulators from the same one).
    ///
    /// # Errors
    /// A model MuJoCo refuses, or one without the Panda or the object.
    pub fn reset_to(&self, seed: u64, init: S::Init) -> Result<SceneEpisode<S>, ScenarioError> {
        let model = self.scene.compose(&self.dir, &init)?;
        let key = ModelKey {
            task: S::NAME.into(),
            config: serde_json::to_string(self.config())
                .map_err(|e| ScenarioError::Render { message: e.to_string() })?,
            assets: self.dir.clone(),
            object_half: S::object_half(&init),
        };
        let arm =
            ArmEpisode::start(S::NAME, seed, model, &S::OBJECT, S::arm_q(&init), S::object_pose(&init))?
                .with_model_key(&key)?
                .with_render_size(self.scene.render_size().map(|r| r as usize));
        Ok(SceneEpisode { arm, init, scene: Arc::clone(&self.scene) })
    }

    /// Runs episode `seed` under `behaviour`: its actor (with the drift where it wanders) or
    /// random actions, perturbed by `perturbation`, within `limits`.
    ///
    /// # Errors
    /// A reset, step or render error naming the seed.
    pub fn episode(
        &self,
        seed: u64,
        behaviour: S::Behaviour,
        perturbation: Perturbation,
        limits: RunLimits,
    ) -> Result<Episode<S::Init, S::Behaviour>, ScenarioError> {
        let mut ep = self.reset(seed)?;
        let init = ep.init;
        let name = self.behaviour_name(behaviour);
        let r = match self.scene.actor(behaviour) {
            None => {
                let mut random = RandomActions::new(S::NAME, seed);
                run(&mut ep, |_| random.action(), perturbation, name, limits)?
            }
            Some(mut actor) => {
                let mut wander = S::wanders(behaviour).then(|| Wander::new(S::NAME, seed));
                let act = |e: &SceneEpisode<S>| {
                    let a = actor(e.arm());
                    wander.as_mut().map_or(a, |w| w.apply(a))
                };
                run(&mut ep, act, perturbation, name, limits)?
            }
        };
        Ok(Episode::new(seed, init, behaviour, r))
    }
}

/// One episode of a robosuite task in progress.
pub struct SceneEpisode<S: ArmScene> {
    arm: ArmEpisode,
    init: S::Init,
    scene: Arc<S>,
}

impl<S: ArmScene> SceneEpisode<S> {
    /// The arm, the object and their state.
    pub fn arm(&self) -> &ArmEpisode {
        &self.arm
    }

    /// The arm, mutably (to step and render).
    pub fn arm_mut(&mut self) -> &mut ArmEpisode {
        &mut self.arm
    }

    /// The initial state the episode started from.
    pub fn init(&self) -> &S::Init {
        &self.init
    }

    /// The scene.
    pub fn scene(&self) -> &S {
        &self.scene
    }

    /// One control step (robomimic's 7-D action).
    ///
    /// # Errors
    /// A non-finite action, or a state that became non-finite (naming seed and step).
    pub fn step(&mut self, action: &[f64; 7]) -> Result<(), ScenarioError> {
        self.arm.step(action)
    }

    /// The task's success check on the current state.
    pub fn success(&self) -> bool {
        self.scene.success(&self.arm)
    }

    /// The state row ([`ArmScene::STATE_COLUMNS`]).
    pub fn state(&self) -> Vec<f64> {
        self.arm.state()
    }

    /// The agentview camera's `size`² RGB image, upright.
    ///
    /// # Errors
    /// [`ScenarioError::Render`] when no offscreen GL context can be made.
    pub fn render(&mut self, size: usize) -> Result<Vec<u8>, ScenarioError> {
        self.arm.render(size)
    }
}

/// Runs `ep` under `act` with `perturbation`; `stream` names the behaviour for
/// the noise's random stream.
///
/// # Errors
/// A step error (naming the seed and step), or a render failure.
pub fn run<S: ArmScene>(
    ep: &mut SceneEpisode<S>,
    mut act: impl FnMut(&SceneEpisode<S>) -> [f64; 7],
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
