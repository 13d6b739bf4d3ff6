//! Assembles robosuite's scenes from robosuite's own asset files with MuJoCo's
//! model-editing API (mjSpec and attach), as robosuite's Python model builder does.
//!
//! The composed model matches what `robosuite.make("Lift", robots="Panda")` (1.5.2,
//! default arguments) hands to MuJoCo:
//! - robosuite's global options (`models/assets/base.xml`): elliptic cones,
//!   impratio 20, air density 1.2 and viscosity 2e-5, timestep 0.002 s;
//! - the arena file, resized as robosuite's `TableArena` does (table top at
//!   `table_offset`, 0.8 × 0.8 × 0.05 m, friction (1, 0.005, 0.0001), legs);
//! - the Panda (`robots/panda/robot.xml`) under the prefix `robot0_`, its base at
//!   (−0.16 − table_length / 2, 0, 0.912), with robosuite's per-joint defaults
//!   (damping 0.1 ×5, 0.01 ×2; frictionloss 0.1; armature 5 / (i + 1));
//! - the Rethink mount (`bases/rethink_mount.xml`) under `fixed_mount0_`, and the
//!   Panda gripper (`grippers/panda_gripper.xml`) under `gripper0_right_` on the
//!   arm's `right_hand` body;
//! - the task's objects, added by the task.
//!
//! robosuite also adds two mocap "eef target" markers (visual only, hidden) and
//! renames unnamed visual geoms; neither changes the physics, so neither is
//! reproduced.

use std::path::{Path, PathBuf};

use mujoco_rs::prelude::*;

use crate::error::ScenarioError;
use crate::robosuite::visual::Visual;

/// The Panda's joint names in the composed model, in qpos order.
pub const ARM_JOINTS: [&str; 7] = [
    "robot0_joint1",
    "robot0_joint2",
    "robot0_joint3",
    "robot0_joint4",
    "robot0_joint5",
    "robot0_joint6",
    "robot0_joint7",
];
/// The gripper's finger joints.
pub const FINGER_JOINTS: [&str; 2] = ["gripper0_right_finger_joint1", "gripper0_right_finger_joint2"];
/// The site the arm controller tracks (robosuite's `grip_site`).
pub const GRIP_SITE: &str = "gripper0_right_grip_site";
/// The arm's base site: the controller subtracts its velocity (zero on a fixed mount).
pub const ARM_CENTER_SITE: &str = "robot0_right_center";

/// The Panda's joint damping as `robosuite.models.robots.Panda` sets it.
const ARM_DAMPING: [f64; 7] = [0.1, 0.1, 0.1, 0.1, 0.1, 0.01, 0.01];

/// robosuite's global physics options (base.xml) plus its 0.002 s timestep,
/// put into the arena file (the root of the composed scene).
/// The `<visual>` element follows, from [`Visual::xml`].
const BASE_OPTIONS: &str = r#"
  <compiler angle="radian" inertiagrouprange="0 0" autolimits="true"/>
  <option timestep="0.002" impratio="20" cone="elliptic" density="1.2" viscosity="0.00002"/>
  <size memory="64M"/>
  "#;

/// The table of robosuite's `TableArena`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Table {
    /// Full size (x, y, thickness), m.
    pub full_size: [f64; 3],
    /// Sliding, torsional and rolling friction.
    pub friction: [f64; 3],
    /// Where the table's top surface centre is, m.
    pub offset: [f64; 3],
}

impl Table {
    /// Lift's table: robosuite's defaults.
    pub const LIFT: Table =
        Table { full_size: [0.8, 0.8, 0.05], friction: [1.0, 5e-3, 1e-4], offset: [0.0, 0.0, 0.8] };

    /// The table top's height, m.
    pub fn top(&self) -> f64 {
        self.offset[2]
    }
}

/// A spec being composed, with the asset folder it reads from.
pub struct SceneBuilder {
    spec: MjSpec,
    dir: PathBuf,
}

fn model_err(message: impl std::fmt::Display) -> ScenarioError {
    ScenarioError::Model { scenario: "robosuite".into(), message: message.to_string() }
}

fn load(dir: &Path, rel: &str) -> Result<MjSpec, ScenarioError> {
    let path = dir.join(rel);
    MjSpec::from_xml(&path).map_err(|e| model_err(format!("{}: {e}", path.display())))
}

/// Loads an arena file as the root of a scene: robosuite's global options go in
/// and its relative texture paths are made absolute (the text is parsed from
/// memory, so MuJoCo has no file to resolve them against).
fn load_root(dir: &Path, rel: &str, visual: &Visual) -> Result<MjSpec, ScenarioError> {
    let path = dir.join(rel);
    let text =
        std::fs::read_to_string(&path).map_err(|source| ScenarioError::Io { path: path.clone(), source })?;
    let textures = dir.join("textures");
    let text = text.replace("file=\"../textures/", &format!("file=\"{}/", textures.display()));
    let Some(open) = text.find("<mujoco").and_then(|i| text[i..].find('>').map(|j| i + j + 1)) else {
        return Err(model_err(format!("{}: no <mujoco> element", path.display())));
    };
    let text = visual.arena(&format!("{}{BASE_OPTIONS}{}\n{}", &text[..open], visual.xml(), &text[open..]));
    MjSpec::from_xml_string(&text).map_err(|e| model_err(format!("{}: {e}", path.display())))
}

fn missing(dir: &Path, rel: &str, kind: &'static str, name: &str) -> ScenarioError {
    ScenarioError::MissingElement { file: dir.join(rel), kind, name: name.into() }
}

impl SceneBuilder {
    /// A scene rooted in robosuite's table arena (`arenas/table_arena.xml`) with
    /// robosuite's global options, the table resized as robosuite's
    /// `TableArena(table_full_size, table_friction, table_offset)` resizes it.
    ///
    /// # Errors
    /// The file is missing, lacks an element robosuite resizes, or MuJoCo refuses it.
    pub fn table_arena(dir: &Path, t: &Table, visual: &Visual) -> Result<Self, ScenarioError> {
        let rel = "arenas/table_arena.xml";
        let mut arena = load_root(dir, rel, visual)?;
        let half = [t.full_size[0] / 2.0, t.full_size[1] / 2.0, t.full_size[2] / 2.0];
        // The body sits half a thickness under the top surface.
        let centre = [t.offset[0], t.offset[1], t.offset[2] - half[2]];
        arena.body_mut("table").ok_or_else(|| missing(dir, rel, "body", "table"))?.with_pos(centre);
        for g in ["table_collision", "table_visual"] {
            let geom = arena.geom_mut(g).ok_or_else(|| missing(dir, rel, "geom", g))?;
            geom.with_size(half);
            if g == "table_collision" {
                geom.with_friction(t.friction);
            }
        }
        arena
            .site_mut("table_top")
            .ok_or_else(|| missing(dir, rel, "site", "table_top"))?
            .with_pos([0.0, 0.0, half[2]]);
        // Legs 0.1 m in from each corner, reaching from the floor to the underside:
        // robosuite's TableArena.configure_location.
        let (dx, dy) = ([0.1, -0.1, -0.1, 0.1], [0.1, 0.1, -0.1, -0.1]);
        let leg_half = (t.offset[2] - half[2]) / 2.0;
        for i in 0..4 {
            let name = format!("table_leg{}_visual", i + 1);
            let x = if dx[i] > 0.0 { half[0] - dx[i] } else { -half[0] - dx[i] };
            let y = if dy[i] > 0.0 { half[1] - dy[i] } else { -half[1] - dy[i] };
            arena
                .geom_mut(&name)
                .ok_or_else(|| missing(dir, rel, "geom", &name))?
                .with_pos([x, y, -leg_half])
                .with_size([0.025, leg_half, 0.0]);
        }
        Ok(Self { spec: arena, dir: dir.to_path_buf() })
    }

    /// A scene rooted in robosuite's bins arena (`arenas/bins_arena.xml`) with
    /// robosuite's global options. PickPlace's defaults put the bins where the
    /// file does, so nothing is moved.
    ///
    /// # Errors
    /// The file is missing or MuJoCo refuses it.
    pub fn bins_arena(dir: &Path, visual: &Visual) -> Result<Self, ScenarioError> {
        Ok(Self { spec: load_root(dir, "arenas/bins_arena.xml", visual)?, dir: dir.to_path_buf() })
    }

    /// Attaches an object given as MJCF text under `prefix` (robosuite's object
    /// naming: `cube_`, `Can_`, `VisualCan_`, ...).
    ///
    /// # Errors
    /// MuJoCo refuses the text or the attachment.
    pub fn attach_object(&mut self, prefix: &str, mjcf: &str) -> Result<(), ScenarioError> {
        let mut spec =
            MjSpec::from_xml_string(mjcf).map_err(|e| model_err(format!("object {prefix}: {e}")))?;
        self.spec
            .world_body_mut()
            .attach_by_deep_copy(&mut spec, prefix, "")
            .map_err(|e| model_err(format!("object {prefix}: {e}")))?;
        Ok(())
    }

    /// Adds the Panda on its Rethink mount with the Panda gripper, its base at
    /// `base` (world frame), as robosuite's `Lift` places it.
    ///
    /// # Errors
    /// An asset file is missing an element, or MuJoCo refuses an attachment.
    pub fn panda(&mut self, base: [f64; 3]) -> Result<(), ScenarioError> {
        let mut robot = load(&self.dir, "robots/panda/robot.xml")?;
        self.spec
            .world_body_mut()
            .attach_by_deep_copy(&mut robot, "robot0_", "")
            .map_err(|e| model_err(format!("robots/panda/robot.xml: {e}")))?;
        let rel = "robots/panda/robot.xml";
        self.spec
            .body_mut("robot0_base")
            .ok_or_else(|| missing(&self.dir, rel, "body", "base"))?
            .with_pos(base);
        for (i, name) in ARM_JOINTS.iter().enumerate() {
            let j = self.spec.joint_mut(name).ok_or_else(|| missing(&self.dir, rel, "joint", name))?;
            j.damping_mut()[0] = ARM_DAMPING[i];
            j.set_frictionloss(0.1);
            j.set_armature(5.0 / (i as f64 + 1.0));
        }
        let mut gripper = load(&self.dir, "grippers/panda_gripper.xml")?;
        self.spec
            .body_mut("robot0_right_hand")
            .ok_or_else(|| missing(&self.dir, rel, "body", "right_hand"))?
            .attach_by_deep_copy(&mut gripper, "gripper0_right_", "")
            .map_err(|e| model_err(format!("grippers/panda_gripper.xml: {e}")))?;
        let mut mount = load(&self.dir, "bases/rethink_mount.xml")?;
        self.spec
            .body_mut("robot0_base")
            .ok_or_else(|| missing(&self.dir, rel, "body", "base"))?
            .attach_by_deep_copy(&mut mount, "fixed_mount0_", "")
            .map_err(|e| model_err(format!("bases/rethink_mount.xml: {e}")))?;
        // The mount's top sits 0.01 m under the robot's base (its top_offset).
        self.spec
            .body_mut("fixed_mount0_base")
            .ok_or_else(|| missing(&self.dir, "bases/rethink_mount.xml", "body", "base"))?
            .with_pos([0.0, 0.0, 0.01]);
        Ok(())
    }

    /// The spec, for the task to add its objects.
    pub fn spec_mut(&mut self) -> &mut MjSpec {
        &mut self.spec
    }

    /// The asset folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Compiles the composed scene, keeping the spec for the next compile.
    ///
    /// # Errors
    /// [`ScenarioError::Model`] with MuJoCo's message.
    pub fn compile_ref(&mut self, scenario: &str) -> Result<MjModel, ScenarioError> {
        self.spec
            .compile()
            .map_err(|e| ScenarioError::Model { scenario: scenario.into(), message: e.to_string() })
    }

    /// Compiles the composed scene.
    ///
    /// # Errors
    /// [`ScenarioError::Model`] with MuJoCo's message.
    pub fn compile(mut self, scenario: &str) -> Result<MjModel, ScenarioError> {
        self.spec
            .compile()
            .map_err(|e| ScenarioError::Model { scenario: scenario.into(), message: e.to_string() })
    }
}
