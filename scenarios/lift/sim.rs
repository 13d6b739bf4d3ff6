//! The Lift reference simulator: robosuite's scene composed per episode, its
//! seeded reset, the OSC_POSE control step, the agentview render and the
//! success check.
//!
//! The cube's size is drawn per episode (robosuite draws it whenever it rebuilds
//! the model, which its default hard reset does every episode), so each episode
//! compiles its own model; MuJoCo's asset cache keeps that near 0.1 s.

use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use harness::seed::{derive, fnv1a};
use mujoco_rs::prelude::*;
use mujoco_rs::renderer::MjRenderer;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use super::config::LiftConfig;
use crate::error::ScenarioError;
use crate::robosuite::assets::assets_dir;
use crate::robosuite::osc::{Osc, PandaIndex};
use crate::robosuite::scene::{SceneBuilder, Table};

/// The Panda's initial joints in robosuite (`Panda.init_qpos`).
pub const PANDA_INIT_QPOS: [f64; 7] = [
    0.0,
    std::f64::consts::PI / 16.0,
    0.0,
    -std::f64::consts::PI / 2.0 - std::f64::consts::PI / 3.0,
    0.0,
    std::f64::consts::PI - 0.2,
    std::f64::consts::PI / 4.0,
];
/// The gripper's initial finger positions (`PandaGripper.init_qpos`).
pub const GRIPPER_INIT_QPOS: [f64; 2] = [0.020833, -0.020833];

/// Names of the state columns, in order.
pub const STATE_COLUMNS: [&str; 23] = [
    "cube_x", "cube_y", "cube_z", "cube_qw", "cube_qx", "cube_qy", "cube_qz", "eef_x", "eef_y", "eef_z",
    "eef_qw", "eef_qx", "eef_qy", "eef_qz", "finger_1", "finger_2", "joint_1", "joint_2", "joint_3",
    "joint_4", "joint_5", "joint_6", "joint_7",
];

/// An episode's initial state: a pure function of the config and the seed.
#[derive(Clone, Copy, Debug, PartialEq)]
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
        let mut arm_q = PANDA_INIT_QPOS;
        for q in &mut arm_q {
            let n: f64 = rng.sample(StandardNormal);
            *q += cfg.init_noise * n;
        }
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
    let mut b = SceneBuilder::table_arena(dir, &table)?;
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
    let mut spec = MjSpec::from_xml_string(&cube)
        .map_err(|e| ScenarioError::Model { scenario: "lift".into(), message: format!("cube: {e}") })?;
    b.spec_mut()
        .world_body_mut()
        .attach_by_deep_copy(&mut spec, "cube_", "")
        .map_err(|e| ScenarioError::Model { scenario: "lift".into(), message: format!("cube: {e}") })?;
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
        let model = Arc::new(lift_model(&self.cfg, &self.dir, init.cube_half)?);
        let index = PandaIndex::new(&model)?;
        let cube = model.body("cube_main").map(|b| b.id).ok_or_else(|| ScenarioError::Model {
            scenario: "lift".into(),
            message: "no body 'cube_main'".into(),
        })?;
        let cube_joint = model.joint("cube_joint0").map(|j| j.id).unwrap_or_default();
        let cube_qpos = model.jnt_qposadr()[cube_joint] as usize;
        let mut data = MjData::new(model.clone());
        {
            let q = data.qpos_mut();
            for (i, &a) in index.arm_qpos.iter().enumerate() {
                q[a] = init.arm_q[i];
            }
            for (i, &a) in index.finger_qpos.iter().enumerate() {
                q[a] = GRIPPER_INIT_QPOS[i];
            }
            q[cube_qpos..cube_qpos + 3].copy_from_slice(&init.cube_pos);
            q[cube_qpos + 3..cube_qpos + 7].copy_from_slice(&init.cube_quat);
        }
        data.forward();
        let osc = Osc::new(&data, index);
        Ok(LiftEpisode {
            seed,
            step: 0,
            data,
            osc,
            cube,
            table_top: self.cfg.table_offset[2],
            cfg: self.cfg.clone(),
            init,
        })
    }
}

/// One Lift episode in progress.
pub struct LiftEpisode {
    seed: u64,
    step: u32,
    data: MjData<Arc<MjModel>>,
    osc: Osc,
    cube: usize,
    table_top: f64,
    cfg: LiftConfig,
    init: LiftInit,
}

impl LiftEpisode {
    /// The episode's seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Control steps taken.
    pub fn steps(&self) -> u32 {
        self.step
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
        if action.iter().any(|v| !v.is_finite()) {
            return Err(ScenarioError::NonFinite {
                scenario: "lift".into(),
                seed: self.seed,
                step: self.step,
                detail: format!("action {action:?}"),
            });
        }
        self.osc.step(&mut self.data, action);
        self.step += 1;
        let bad =
            |what: &str, v: &[f64]| v.iter().position(|x| !x.is_finite()).map(|i| format!("{what}[{i}]"));
        if let Some(detail) = bad("qpos", self.data.qpos()).or_else(|| bad("qvel", self.data.qvel())) {
            return Err(ScenarioError::NonFinite {
                scenario: "lift".into(),
                seed: self.seed,
                step: self.step,
                detail,
            });
        }
        Ok(())
    }

    /// The cube's centre, m.
    pub fn cube_pos(&self) -> [f64; 3] {
        self.data.xpos()[self.cube]
    }

    /// The cube's orientation (w, x, y, z).
    pub fn cube_quat(&self) -> [f64; 4] {
        self.data.xquat()[self.cube]
    }

    /// The grip site's position, m.
    pub fn eef_pos(&self) -> [f64; 3] {
        self.data.site_xpos()[self.osc.index().grip_site]
    }

    /// The grip site's rotation matrix (row-major).
    pub fn eef_mat(&self) -> [[f64; 3]; 3] {
        let x = self.data.site_xmat()[self.osc.index().grip_site];
        [[x[0], x[1], x[2]], [x[3], x[4], x[5]], [x[6], x[7], x[8]]]
    }

    /// The finger joints, m (open: ±0.04).
    pub fn fingers(&self) -> [f64; 2] {
        self.osc.index().finger_qpos.map(|a| self.data.qpos()[a])
    }

    /// The arm's joints, rad.
    pub fn arm_q(&self) -> [f64; 7] {
        self.osc.index().arm_qpos.map(|a| self.data.qpos()[a])
    }

    /// robosuite's `Lift._check_success`: the cube's centre is more than
    /// `success_height` above the table top.
    pub fn success(&self) -> bool {
        self.cube_pos()[2] > self.table_top + self.cfg.success_height
    }

    /// The state row ([`STATE_COLUMNS`]).
    pub fn state(&self) -> Vec<f64> {
        let mut s = Vec::with_capacity(STATE_COLUMNS.len());
        s.extend(self.cube_pos());
        s.extend(self.cube_quat());
        s.extend(self.eef_pos());
        s.extend(mat_to_quat(&self.eef_mat()));
        s.extend(self.fingers());
        s.extend(self.arm_q());
        s
    }

    /// The agentview camera's `size`² RGB image, upright (rows top to bottom).
    ///
    /// # Errors
    /// [`ScenarioError::Render`] when no offscreen GL context can be made.
    pub fn render(&mut self, size: usize) -> Result<Vec<u8>, ScenarioError> {
        render_agentview(&mut self.data, size)
    }
}

/// A rotation matrix's quaternion (w, x, y, z), w ≥ 0.
pub fn mat_to_quat(m: &[[f64; 3]; 3]) -> [f64; 4] {
    let tr = m[0][0] + m[1][1] + m[2][2];
    let q = if tr > 0.0 {
        let s = (tr + 1.0).sqrt() * 2.0;
        [0.25 * s, (m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
        [(m[2][1] - m[1][2]) / s, 0.25 * s, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s]
    } else if m[1][1] > m[2][2] {
        let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
        [(m[0][2] - m[2][0]) / s, (m[0][1] + m[1][0]) / s, 0.25 * s, (m[1][2] + m[2][1]) / s]
    } else {
        let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
        [(m[1][0] - m[0][1]) / s, (m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, 0.25 * s]
    };
    if q[0] < 0.0 { q.map(|v| -v) } else { q }
}

thread_local! {
    /// One offscreen renderer per thread and image size (GL contexts are not `Send`).
    static RENDERER: RefCell<Option<(usize, MjRenderer)>> = const { RefCell::new(None) };
}

/// Renders robosuite's `agentview` camera, showing only visual geoms (group 1)
/// and no sites, as robosuite's offscreen renderer does by default.
fn render_agentview(data: &mut MjData<Arc<MjModel>>, size: usize) -> Result<Vec<u8>, ScenarioError> {
    let err = |e: &dyn std::fmt::Display| ScenarioError::Render { message: e.to_string() };
    let cam = data.model().camera("agentview").map(|c| c.id).ok_or_else(|| err(&"no camera 'agentview'"))?;
    RENDERER.with(|cell| {
        let mut slot = cell.borrow_mut();
        if slot.as_ref().is_none_or(|(s, _)| *s != size) {
            let side = u32::try_from(size).map_err(|e| err(&e))?;
            let mut r = MjRenderer::builder()
                .width(side)
                .height(side)
                .rgb(true)
                .depth(false)
                .camera(MjvCamera::new_fixed(cam))
                .build(data.model())
                .map_err(|e| err(&e))?;
            let o = r.opts_mut();
            o.geomgroup = [0, 1, 0, 0, 0, 0];
            o.sitegroup = [0; 6];
            *slot = Some((size, r));
        }
        let (_, r) = slot.as_mut().expect("set above");
        r.sync_data(data).map_err(|e| err(&e))?;
        r.render().map_err(|e| err(&e))?;
        // mujoco-rs hands the rows over top to bottom: the image is upright, as
        // robomimic stores agentview after flipping robosuite's raw (OpenGL-order)
        // observation.
        let rgb = r.rgb_flat().ok_or_else(|| err(&"renderer returned no RGB image"))?;
        Ok(rgb.to_vec())
    })
}
