//! Can's scene for the robosuite tasks' simulator ([`ArmSim`]; robosuite's `PickPlaceCan`):
//! the bins arena, the Panda, the Coke can in bin 1 and the four translucent target markers
//! in bin 2, the can's seeded placement and the success check.
//!
//! robosuite's `PickPlaceCan` builds all four PickPlace objects and parks the
//! three it does not use at (10, 10, 10), far outside the scene; they never
//! touch the robot or the can, so they are left out here.

use std::path::Path;

use harness::seed::{derive, fnv1a};
use mujoco_rs::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::config::CanConfig;
use super::rollout::CanBehaviour;
use crate::error::ScenarioError;
use crate::robosuite::arm_sim::{Actor, ArmScene, ArmSim, SceneEpisode};
use crate::robosuite::assets::assets_dir;
use crate::robosuite::episode::{ArmEpisode, ObjectNames, noisy_init_qpos};
use crate::robosuite::rollout::Episode;
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

/// Can's scene: its parameters and the model compiled once for every episode (the scene does
/// not change between episodes). The simulator is the robosuite tasks' one ([`ArmSim`]).
pub struct Can {
    cfg: CanConfig,
    model: MjModel,
}

/// The Can simulator.
pub type CanSim = ArmSim<Can>;
/// One Can episode in progress.
pub type CanEpisode = SceneEpisode<Can>;
/// A finished Can episode.
pub type CanEpisodeRecord = Episode<CanInit, CanBehaviour>;

impl ArmSim<Can> {
    /// Checks the config, finds the assets and compiles the scene.
    ///
    /// # Errors
    /// A missing asset folder, an invalid config, or a model MuJoCo refuses.
    pub fn new(cfg: CanConfig) -> Result<Self, ScenarioError> {
        cfg.validate(Path::new("<can>"))?;
        let dir = assets_dir()?;
        let model = can_model(&cfg, &dir)?;
        Ok(Self::of(Can { cfg, model }, dir))
    }
}

impl Can {
    /// Whether the can lies in its target quadrant of bin 2, as robosuite's
    /// `PickPlace.not_in_bin` bounds it (strictly inside in x and y, its origin
    /// between the bin's reference height and 0.1 m above).
    pub fn in_target_bin(&self, arm: &ArmEpisode) -> bool {
        let p = arm.object_pos();
        let (x, y) = self.cfg.quadrant(3);
        let z = self.cfg.bin2_pos[2];
        x[0] < p[0] && p[0] < x[1] && y[0] < p[1] && p[1] < y[1] && z < p[2] && p[2] < z + 0.1
    }
}

impl SceneEpisode<Can> {
    /// Whether the can lies in its target quadrant of bin 2 ([`Can::in_target_bin`]).
    pub fn in_target_bin(&self) -> bool {
        self.scene().in_target_bin(self.arm())
    }
}

impl ArmScene for Can {
    type Config = CanConfig;
    type Init = CanInit;
    type Behaviour = CanBehaviour;
    const NAME: &'static str = "can";
    const STATE_COLUMNS: &'static [&'static str] = &STATE_COLUMNS;
    const OBJECT: ObjectNames<'static> = ObjectNames { body: "Can_main", joint: "Can_joint0" };

    fn config(&self) -> &CanConfig {
        &self.cfg
    }

    fn max_steps(&self) -> usize {
        self.cfg.max_steps
    }

    fn render_size(&self) -> Option<u32> {
        self.cfg.visual.render_size
    }

    fn place(&self, seed: u64) -> CanInit {
        CanInit::draw(&self.cfg, seed)
    }

    fn arm_q(init: &CanInit) -> [f64; 7] {
        init.arm_q
    }

    fn object_pose(init: &CanInit) -> [f64; 7] {
        let ([x, y, z], [qw, qx, qy, qz]) = (init.can_pos, init.can_quat);
        [x, y, z, qw, qx, qy, qz]
    }

    fn object_half(_: &CanInit) -> Option<[f64; 3]> {
        None
    }

    /// The one model compiled at construction (MuJoCo copies it).
    fn compose(&self, _dir: &Path, _init: &CanInit) -> Result<MjModel, ScenarioError> {
        Ok(self.model.clone())
    }

    /// robosuite's `PickPlace._check_success` for the can alone: in its target
    /// quadrant, with the gripper more than `release_distance` away.
    fn success(&self, arm: &ArmEpisode) -> bool {
        let (p, e) = (arm.object_pos(), arm.eef_pos());
        let d = ((p[0] - e[0]).powi(2) + (p[1] - e[1]).powi(2) + (p[2] - e[2]).powi(2)).sqrt();
        self.in_target_bin(arm) && d > self.cfg.release_distance
    }

    fn behaviours(&self) -> &'static [(&'static str, CanBehaviour)] {
        &CanBehaviour::ALL
    }

    fn actor(&self, behaviour: CanBehaviour) -> Option<Actor<'_>> {
        behaviour.actor(&self.cfg)
    }

    fn wanders(behaviour: CanBehaviour) -> bool {
        behaviour == CanBehaviour::Explore
    }
}
