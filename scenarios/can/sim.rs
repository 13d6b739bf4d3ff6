//! The Can reference simulator (robosuite's `PickPlaceCan`): the bins arena, the
//! Panda, the Coke can in bin 1 and the four translucent target markers in bin
//! 2, its seeded reset and success check.
//!
//! robosuite's `PickPlaceCan` builds all four PickPlace objects and parks the
//! three it does not use at (10, 10, 10), far outside the scene; they never
//! touch the robot or the can, so they are left out here.

use std::path::{Path, PathBuf};

use harness::seed::{derive, fnv1a};
use mujoco_rs::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::config::CanConfig;
use crate::error::ScenarioError;
use crate::robosuite::assets::assets_dir;
use crate::robosuite::episode::{ArmEpisode, ObjectNames, noisy_init_qpos};
use crate::robosuite::render_pool::ModelKey;
use crate::robosuite::scene::SceneBuilder;

/// Names of the state columns, in order.
pub const STATE_COLUMNS: [&str; 23] = [
    "can_x", "can_y", "can_z", "can_qw", "can_qx", "can_qy", "can_qz", "eef_x", "eef_y", "eef_z", "eef_qw",
    "eef_qx", "eef_qy", "eef_qz", "finger_1", "finger_2", "joint_1", "joint_2", "joint_3", "joint_4",
    "joint_5", "joint_6", "joint_7",
];

/// The target markers robosuite shows in bin 2's quadrants: name, mesh file,
/// mesh scale, and the height of the object's origin above its bottom (its
/// visual file's `bottom_site`).
const MARKERS: [(&str, &str, f64, f64); 4] = [
    ("VisualMilk_", "milk.stl", 0.9, 0.085),
    ("VisualBread_", "bread.stl", 0.8, 0.045),
    ("VisualCereal_", "cereal.stl", 1.0, 0.10),
    ("VisualCan_", "can.stl", 1.0, 0.06),
];

/// An episode's initial state: a pure function of the config and the seed.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct CanInit {
    /// The can's origin, m.
    pub can_pos: [f64; 3],
    /// The can's orientation (w, x, y, z): a rotation about z.
    pub can_quat: [f64; 4],
    /// The arm's joints.
    pub arm_q: [f64; 7],
}

impl CanInit {
    /// Draws the initial state of episode `seed`: the arm's joint noise, then the
    /// can's placement in bin 1 (uniform x, y at least the margin plus the can's
    /// radius inside the edges, a uniform z rotation, standing on the bin's
    /// reference height as robosuite's `UniformRandomSampler` puts it).
    pub fn draw(cfg: &CanConfig, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(derive(seed, &[fnv1a("can/reset")]));
        let arm_q = noisy_init_qpos(&mut rng, cfg.init_noise);
        let half = [0, 1].map(|i| cfg.bin_size[i] / 2.0 - cfg.placement_margin - cfg.can_radius);
        let x = cfg.bin1_pos[0] + half[0] * (2.0 * rng.random::<f64>() - 1.0);
        let y = cfg.bin1_pos[1] + half[1] * (2.0 * rng.random::<f64>() - 1.0);
        let yaw = std::f64::consts::TAU * rng.random::<f64>();
        let z = cfg.bin1_pos[2] - cfg.can_bottom;
        Self { can_pos: [x, y, z], can_quat: [(yaw / 2.0).cos(), 0.0, 0.0, (yaw / 2.0).sin()], arm_q }
    }
}

/// The Can scene: robosuite's bins arena, Panda, can and target markers.
///
/// # Errors
/// Missing assets or a model MuJoCo refuses.
pub fn can_model(cfg: &CanConfig, dir: &Path) -> Result<MjModel, ScenarioError> {
    let mut b = SceneBuilder::bins_arena(dir, &cfg.visual)?;
    b.panda(cfg.robot_base())?;
    let meshes = dir.join("objects/meshes");
    // The markers sit at their quadrant's centre, their bottom on bin 2's reference height.
    for (i, (prefix, file, scale, lift)) in MARKERS.iter().enumerate() {
        let (x, y) = cfg.quadrant(i);
        let (cx, cy, cz) = ((x[0] + x[1]) / 2.0, (y[0] + y[1]) / 2.0, cfg.bin2_pos[2] + lift);
        let xml = format!(
            r#"<mujoco><asset><mesh name="mesh" file="{}" scale="{scale} {scale} {scale}"/></asset>
<worldbody><body name="main" pos="{cx} {cy} {cz}">
  <geom name="g0" type="mesh" mesh="mesh" contype="0" conaffinity="0" group="1" rgba="0.8 0.8 0.8 0.3" mass="0"/>
</body></worldbody></mujoco>"#,
            meshes.join(file).display()
        );
        b.attach_object(prefix, &xml)?;
    }
    // robosuite's CanObject: the collision mesh (can.msh, density 100, soft
    // contacts) and its visual twin with the Coke texture, on a damped free joint.
    let can = format!(
        r#"<mujoco><asset>
  <mesh name="can_mesh" file="{}"/>
  <texture name="tex-can" file="{}" type="2d"/>
  <material name="coke" reflectance="0.7" texrepeat="5 5" texture="tex-can" texuniform="true"/>
</asset><worldbody><body name="main">
  <joint name="joint0" type="free" damping="0.0005"/>
  <geom name="g0" type="mesh" mesh="can_mesh" group="0" condim="4" friction="0.95 0.3 0.1" solref="0.001 1" solimp="0.998 0.998 0.001" rgba="0.5 0 0 1" density="100"/>
  <geom name="g0_visual" type="mesh" mesh="can_mesh" group="1" contype="0" conaffinity="0" condim="4" friction="0.95 0.3 0.1" solref="0.001 1" solimp="0.998 0.998 0.001" mass="0" material="coke"/>
</body></worldbody></mujoco>"#,
        meshes.join("can.msh").display(),
        dir.join("textures/soda.png").display()
    );
    b.attach_object("Can_", &can)?;
    b.compile("can")
}

/// The Can task's simulator factory: one compiled model for every episode (the
/// scene does not change between episodes).
pub struct CanSim {
    cfg: CanConfig,
    model: MjModel,
    /// The asset folder it was compiled from (a render worker compiles the same).
    dir: PathBuf,
}

impl CanSim {
    /// Checks the config, finds the assets and compiles the scene.
    ///
    /// # Errors
    /// A missing asset folder, an invalid config, or a model MuJoCo refuses.
    pub fn new(cfg: CanConfig) -> Result<Self, ScenarioError> {
        cfg.validate(Path::new("<can>"))?;
        let dir: PathBuf = assets_dir()?;
        let model = can_model(&cfg, &dir)?;
        Ok(Self { cfg, model, dir })
    }

    /// The config.
    pub fn config(&self) -> &CanConfig {
        &self.cfg
    }

    /// Episode `seed` at its initial state.
    ///
    /// # Errors
    /// A model without the Panda or the can (never, for the composed scene).
    pub fn reset(&self, seed: u64) -> Result<CanEpisode, ScenarioError> {
        self.reset_to(seed, CanInit::draw(&self.cfg, seed))
    }

    /// An episode from a given initial state.
    ///
    /// # Errors
    /// As [`CanSim::reset`].
    pub fn reset_to(&self, seed: u64, init: CanInit) -> Result<CanEpisode, ScenarioError> {
        let model = self.model.clone();
        let [x, y, z] = init.can_pos;
        let [qw, qx, qy, qz] = init.can_quat;
        let names = ObjectNames { body: "Can_main", joint: "Can_joint0" };
        let key = ModelKey {
            task: "can".into(),
            config: serde_json::to_string(&self.cfg)
                .map_err(|e| ScenarioError::Render { message: e.to_string() })?,
            assets: self.dir.clone(),
            object_half: None,
        };
        let arm = ArmEpisode::start("can", seed, model, &names, init.arm_q, [x, y, z, qw, qx, qy, qz])?
            .with_model_key(&key)?
            .with_render_size(self.cfg.visual.render_size.map(|r| r as usize));
        Ok(CanEpisode { arm, cfg: self.cfg.clone(), init })
    }
}

/// One Can episode in progress.
pub struct CanEpisode {
    arm: ArmEpisode,
    cfg: CanConfig,
    init: CanInit,
}

impl CanEpisode {
    /// The arm, the can and their state.
    pub fn arm(&self) -> &ArmEpisode {
        &self.arm
    }

    /// The arm, mutably.
    pub fn arm_mut(&mut self) -> &mut ArmEpisode {
        &mut self.arm
    }

    /// The initial state the episode started from.
    pub fn init(&self) -> &CanInit {
        &self.init
    }

    /// Whether the can lies in its target quadrant of bin 2, as robosuite's
    /// `PickPlace.not_in_bin` bounds it (strictly inside in x and y, its origin
    /// between the bin's reference height and 0.1 m above).
    pub fn in_target_bin(&self) -> bool {
        let p = self.arm.object_pos();
        let (x, y) = self.cfg.quadrant(3);
        let z = self.cfg.bin2_pos[2];
        x[0] < p[0] && p[0] < x[1] && y[0] < p[1] && p[1] < y[1] && z < p[2] && p[2] < z + 0.1
    }

    /// robosuite's `PickPlace._check_success` for the can alone: in its target
    /// quadrant, with the gripper more than `release_distance` away.
    pub fn success(&self) -> bool {
        let (p, e) = (self.arm.object_pos(), self.arm.eef_pos());
        let d = ((p[0] - e[0]).powi(2) + (p[1] - e[1]).powi(2) + (p[2] - e[2]).powi(2)).sqrt();
        self.in_target_bin() && d > self.cfg.release_distance
    }
}
