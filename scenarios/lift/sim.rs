//! Lift's scene for the robosuite tasks' simulator ([`ArmSim`]): robosuite's table arena
//! composed per episode, the cube's seeded placement and the success check.
//!
//! The cube's size is drawn per episode (robosuite draws it whenever it rebuilds
//! the model, which its default hard reset does every episode), so each episode
//! compiles its own model; MuJoCo's asset cache keeps that near 0.1 s.

use std::path::Path;

use harness::seed::{derive, fnv1a};
use mujoco_rs::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::config::LiftConfig;
use super::rollout::LiftBehaviour;
use crate::error::ScenarioError;
use crate::robosuite::arm_sim::{Actor, ArmScene, ArmSim, SceneEpisode};
use crate::robosuite::assets::assets_dir;
use crate::robosuite::episode::{ArmEpisode, ObjectNames, noisy_init_qpos};
use crate::robosuite::rollout::Episode;
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

/// Lift's scene: its parameters. The simulator is the robosuite tasks' one ([`ArmSim`]).
#[derive(Clone, Debug)]
pub struct Lift {
    cfg: LiftConfig,
}

/// The Lift simulator.
pub type LiftSim = ArmSim<Lift>;
/// One Lift episode in progress.
pub type LiftEpisode = SceneEpisode<Lift>;
/// A finished Lift episode.
pub type LiftEpisodeRecord = Episode<LiftInit, LiftBehaviour>;

impl ArmSim<Lift> {
    /// Checks the config and finds the assets.
    ///
    /// # Errors
    /// A missing asset folder, or an invalid config.
    pub fn new(cfg: LiftConfig) -> Result<Self, ScenarioError> {
        cfg.validate(Path::new("<lift>"))?;
        Ok(Self::of(Lift { cfg }, assets_dir()?))
    }
}

impl ArmScene for Lift {
    type Config = LiftConfig;
    type Init = LiftInit;
    type Behaviour = LiftBehaviour;
    const NAME: &'static str = "lift";
    const STATE_COLUMNS: &'static [&'static str] = &STATE_COLUMNS;
    const OBJECT: ObjectNames<'static> = ObjectNames { body: "cube_main", joint: "cube_joint0" };

    fn config(&self) -> &LiftConfig {
        &self.cfg
    }

    fn max_steps(&self) -> usize {
        self.cfg.max_steps
    }

    fn render_size(&self) -> Option<u32> {
        self.cfg.visual.render_size
    }

    fn place(&self, seed: u64) -> LiftInit {
        LiftInit::draw(&self.cfg, seed)
    }

    fn arm_q(init: &LiftInit) -> [f64; 7] {
        init.arm_q
    }

    fn object_pose(init: &LiftInit) -> [f64; 7] {
        let ([x, y, z], [qw, qx, qy, qz]) = (init.cube_pos, init.cube_quat);
        [x, y, z, qw, qx, qy, qz]
    }

    fn object_half(init: &LiftInit) -> Option<[f64; 3]> {
        Some(init.cube_half)
    }

    /// The cube's size is drawn per episode, so each episode compiles its own model.
    fn compose(&self, dir: &Path, init: &LiftInit) -> Result<MjModel, ScenarioError> {
        lift_model(&self.cfg, dir, init.cube_half)
    }

    /// robosuite's `Lift._check_success`: the cube's centre is more than `success_height`
    /// above the table top.
    fn success(&self, arm: &ArmEpisode) -> bool {
        arm.object_pos()[2] > self.cfg.table_offset[2] + self.cfg.success_height
    }

    fn behaviours(&self) -> &'static [(&'static str, LiftBehaviour)] {
        &LiftBehaviour::ALL
    }

    fn actor(&self, behaviour: LiftBehaviour) -> Option<Actor<'_>> {
        behaviour.actor()
    }

    fn wanders(behaviour: LiftBehaviour) -> bool {
        behaviour == LiftBehaviour::Explore
    }
}
