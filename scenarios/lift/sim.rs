//! The Lift reference simulator: robosuite's scene composed per episode, its
//! seeded reset, the OSC_POSE control step, the agentview render and the
//! success check.
//!
//! The cube's size is drawn per episode (robosuite draws it whenever it rebuilds
//! the model, which its default hard reset does every episode), so each episode
//! compiles its own model; MuJoCo's asset cache keeps that near 0.1 s.

use std::path::{Path, PathBuf};

use harness::seed::{derive, fnv1a};
use mujoco_rs::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::config::LiftConfig;
use crate::error::ScenarioError;
use crate::robosuite::assets::assets_dir;
use crate::robosuite::episode::{ArmEpisode, ObjectNames, noisy_init_qpos};
use crate::robosuite::render_pool::ModelKey;
use crate::robosuite::scene::{SceneBuilder, Table};

/// Names of the state columns, in order.
pub const STATE_COLUMNS: [&str; 23] = [
    "cube_x", "cube_y", "cube_z", "cube_qw", "cube_qx", "cube_qy", "cube_qz", "eef_x", "eef_y", "eef_z",
    "eef_qw", "eef_qx", "eef_qy", "eef_qz", "finger_1", "finger_2", "joint_1", "joint_2", "joint_3",
    "joint_4", "joint_5", "joint_6", "joint_7",
];

/// An episode's initial state: a pure function of the config and the seed.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct LiftInit {
    /// The cube's half-sizes, m.
    pub cube_half: [f64; 3],
    /// The cube's centre, m.
    pub cube_pos: [f64; 3],
    /// The cube's orientation (w, x, y, z): a rotation about z.
    pub cube_quat: [f64; 4],
    /// The arm's joints.
    pub arm_q: [f64; 7],
}

impl LiftInit {
    /// Draws the initial state of episode `seed`, in robosuite's order: the cube's
    /// size, the arm's joint noise, then the placement (uniform x, y about the
    /// table centre, a uniform z rotation, the bottom `cube_z_offset` above the top).
    pub fn draw(cfg: &LiftConfig, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(derive(seed, &[fnv1a("lift/reset")]));
        let mut cube_half = [0.0; 3];
        for (i, h) in cube_half.iter_mut().enumerate() {
            *h = cfg.cube_half_min[i] + (cfg.cube_half_max[i] - cfg.cube_half_min[i]) * rng.random::<f64>();
        }
        let arm_q = noisy_init_qpos(&mut rng, cfg.init_noise);
        let u = |rng: &mut ChaCha8Rng, r: [f64; 2]| r[0] + (r[1] - r[0]) * rng.random::<f64>();
        let x = cfg.table_offset[0] + u(&mut rng, cfg.cube_x_range);
        let y = cfg.table_offset[1] + u(&mut rng, cfg.cube_y_range);
        let yaw = std::f64::consts::TAU * rng.random::<f64>();
        let z = cfg.table_offset[2] + cfg.cube_z_offset + cube_half[2];
        let cube_quat = [(yaw / 2.0).cos(), 0.0, 0.0, (yaw / 2.0).sin()];
        Self { cube_half, cube_pos: [x, y, z], cube_quat, arm_q }
    }
}

/// The Lift scene for one cube size: robosuite's table arena, Panda and cube.
///
/// # Errors
/// Missing assets or a model MuJoCo refuses.
pub fn lift_model(cfg: &LiftConfig, dir: &Path, cube_half: [f64; 3]) -> Result<MjModel, ScenarioError> {
    let table =
        Table { full_size: cfg.table_full_size, friction: cfg.table_friction, offset: cfg.table_offset };
    let mut b = SceneBuilder::table_arena(dir, &table, &cfg.visual)?;
    b.panda(cfg.robot_base())?;
    // robosuite's BoxObject("cube", rgba red, material "redwood"), its names under
    // the prefix `cube_` as robosuite's: a collision box
    // (density 1000, default friction and solver settings) and a massless visual
    // twin with the red-wood cube texture, on a free joint.
    let tex = dir.join("textures/red-wood.png");
    let [hx, hy, hz] = cube_half;
    let cube = format!(
        r#"<mujoco><asset>
  <texture type="cube" name="redwood" file="{}"/>
  <material name="redwood_mat" texture="redwood" texrepeat="1 1" specular="0.4" shininess="0.1"/>
</asset><worldbody><body name="main">
  <joint name="joint0" type="free"/>
  <geom name="g0" type="box" size="{hx} {hy} {hz}" group="0" rgba="0.5 0 0 1" density="1000"/>
  <geom name="g0_vis" type="box" size="{hx} {hy} {hz}" group="1" contype="0" conaffinity="0" mass="0" material="redwood_mat"/>
</body></worldbody></mujoco>"#,
        tex.display()
    );
    b.attach_object("cube_", &cube)?;
    b.compile("lift")
}

/// The Lift task's simulator factory.
#[derive(Clone, Debug)]
pub struct LiftSim {
    cfg: LiftConfig,
    dir: PathBuf,
}

impl LiftSim {
    /// Checks the config and finds the assets.
    ///
    /// # Errors
    /// A missing asset folder, or an invalid config.
    pub fn new(cfg: LiftConfig) -> Result<Self, ScenarioError> {
        cfg.validate(Path::new("<lift>"))?;
        Ok(Self { cfg, dir: assets_dir()? })
    }

    /// The config.
    pub fn config(&self) -> &LiftConfig {
        &self.cfg
    }

    /// Episode `seed` at its initial state.
    ///
    /// # Errors
    /// A model MuJoCo refuses.
    pub fn reset(&self, seed: u64) -> Result<LiftEpisode, ScenarioError> {
        self.reset_to(seed, LiftInit::draw(&self.cfg, seed))
    }

    /// An episode from a given initial state (the cross-check with robosuite
    /// starts both simulators from the same one).
    ///
    /// # Errors
    /// A model MuJoCo refuses.
    pub fn reset_to(&self, seed: u64, init: LiftInit) -> Result<LiftEpisode, ScenarioError> {
        let model = lift_model(&self.cfg, &self.dir, init.cube_half)?;
        let [x, y, z] = init.cube_pos;
        let [qw, qx, qy, qz] = init.cube_quat;
        let names = ObjectNames { body: "cube_main", joint: "cube_joint0" };
        let key = ModelKey {
            task: "lift".into(),
            config: serde_json::to_string(&self.cfg)
                .map_err(|e| ScenarioError::Render { message: e.to_string() })?,
            assets: self.dir.clone(),
            object_half: Some(init.cube_half),
        };
        let arm = ArmEpisode::start("lift", seed, model, &names, init.arm_q, [x, y, z, qw, qx, qy, qz])?
            .with_model_key(&key)?
            .with_render_size(self.cfg.visual.render_size.map(|r| r as usize));
        Ok(LiftEpisode {
            arm,
            table_top: self.cfg.table_offset[2],
            success_height: self.cfg.success_height,
            init,
        })
    }
}

/// One Lift episode in progress.
pub struct LiftEpisode {
    arm: ArmEpisode,
    table_top: f64,
    success_height: f64,
    init: LiftInit,
}

impl LiftEpisode {
    /// The arm, the cube and their state.
    pub fn arm(&self) -> &ArmEpisode {
        &self.arm
    }

    /// The arm, mutably.
    pub fn arm_mut(&mut self) -> &mut ArmEpisode {
        &mut self.arm
    }

    /// The initial state the episode started from.
    pub fn init(&self) -> &LiftInit {
        &self.init
    }

    /// One control step (robomimic's 7-D action).
    ///
    /// # Errors
    /// A non-finite action, or a state that became non-finite (naming seed and step).
    pub fn step(&mut self, action: &[f64; 7]) -> Result<(), ScenarioError> {
        self.arm.step(action)
    }

    /// robosuite's `Lift._check_success`: the cube's centre is more than
    /// `success_height` above the table top.
    pub fn success(&self) -> bool {
        self.arm.object_pos()[2] > self.table_top + self.success_height
    }

    /// The state row ([`STATE_COLUMNS`]).
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
