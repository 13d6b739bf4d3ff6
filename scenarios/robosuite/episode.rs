//! One robosuite episode in progress, whatever the task: the Panda on its
//! controller, one free object, the control step with its divergence check, the
//! state row and the agentview render. Lift and Can add their success checks.

use std::sync::Arc;

use mujoco_rs::prelude::*;

use super::osc::{Osc, PandaIndex};
use crate::error::ScenarioError;

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
/// The Panda's initial joints plus Gaussian noise of std `noise` per joint, as
/// robosuite's default `initialization_noise` draws them.
pub fn noisy_init_qpos(rng: &mut impl rand::Rng, noise: f64) -> [f64; 7] {
    PANDA_INIT_QPOS.map(|q| {
        let n: f64 = rng.sample(rand_distr::StandardNormal);
        q + noise * n
    })
}

/// The arm's last body, whose orientation robosuite reports as `robot0_eef_quat`.
pub const HAND_BODY: &str = "robot0_right_hand";
/// The gripper's initial finger positions (`PandaGripper.init_qpos`).
pub const GRIPPER_INIT_QPOS: [f64; 2] = [0.020833, -0.020833];

/// Names of the state columns after the object's seven (position, quaternion).
pub const ROBOT_COLUMNS: [&str; 16] = [
    "eef_x", "eef_y", "eef_z", "eef_qw", "eef_qx", "eef_qy", "eef_qz", "finger_1", "finger_2", "joint_1",
    "joint_2", "joint_3", "joint_4", "joint_5", "joint_6", "joint_7",
];

/// A compiled scene's object: its body and free joint, by robosuite's names.
pub struct ObjectNames<'a> {
    /// The object's body (`cube_main`, `Can_main`).
    pub body: &'a str,
    /// Its free joint.
    pub joint: &'a str,
}

/// One episode in progress.
pub struct ArmEpisode {
    scenario: &'static str,
    seed: u64,
    step: u32,
    data: MjData<Arc<MjModel>>,
    osc: Osc,
    object: usize,
    /// The `robot0_right_hand` body (robosuite's `eef_quat` reads its orientation).
    hand: usize,
    /// The joint positions the data's poses were last computed at (what a frame
    /// shows), for a render worker ([`super::render_pool`]).
    shown: Vec<f64>,
    /// The recipe of the model as a render request names it, for a render worker to
    /// build the same one.
    key: Option<Arc<str>>,
    /// Render at this side, then upsample to the asked size ([`super::visual::Visual::render_size`]).
    render_from: Option<usize>,
}

impl ArmEpisode {
    /// Places the arm at `arm_q`, the fingers at their initial opening and the
    /// object at `pose` (x, y, z, qw, qx, qy, qz), then starts the controller.
    ///
    /// # Errors
    /// [`ScenarioError::Model`] when the model lacks the Panda or the object.
    pub fn start(
        scenario: &'static str,
        seed: u64,
        model: MjModel,
        object: &ObjectNames<'_>,
        arm_q: [f64; 7],
        pose: [f64; 7],
    ) -> Result<Self, ScenarioError> {
        let model = Arc::new(model);
        let index = PandaIndex::new(&model)?;
        let miss = |kind: &str, name: &str| ScenarioError::Model {
            scenario: scenario.into(),
            message: format!("no {kind} '{name}'"),
        };
        let body = model.body(object.body).ok_or_else(|| miss("body", object.body))?.id;
        let joint = model.joint(object.joint).ok_or_else(|| miss("joint", object.joint))?.id;
        let adr = model.jnt_qposadr()[joint] as usize;
        let hand = model.body(HAND_BODY).ok_or_else(|| miss("body", HAND_BODY))?.id;
        let mut data = MjData::new(model.clone());
        {
            let q = data.qpos_mut();
            for (i, &a) in index.arm_qpos.iter().enumerate() {
                q[a] = arm_q[i];
            }
            for (i, &a) in index.finger_qpos.iter().enumerate() {
                q[a] = GRIPPER_INIT_QPOS[i];
            }
            q[adr..adr + 7].copy_from_slice(&pose);
        }
        data.forward();
        let osc = Osc::new(&data, index);
        let shown = data.qpos().to_vec();
        Ok(Self {
            scenario,
            seed,
            step: 0,
            data,
            osc,
            object: body,
            hand,
            shown,
            key: None,
            render_from: None,
        })
    }

    /// Names the recipe of this episode's model, so that render workers
    /// ([`super::render_pool`]) can render its frames; without one it renders itself.
    ///
    /// # Errors
    /// A key that cannot be written as a request.
    pub fn with_model_key(mut self, key: &super::render_pool::ModelKey) -> Result<Self, ScenarioError> {
        self.key = Some(Arc::from(key.text()?));
        Ok(self)
    }

    /// The episode's seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Control steps taken.
    pub fn steps(&self) -> u32 {
        self.step
    }

    /// One control step (robomimic's 7-D action).
    ///
    /// # Errors
    /// A non-finite action, or a state that became non-finite (naming seed and step).
    pub fn step(&mut self, action: &[f64; 7]) -> Result<(), ScenarioError> {
        let fail = |step: u32, detail: String| ScenarioError::NonFinite {
            scenario: self.scenario.into(),
            seed: self.seed,
            step,
            detail,
        };
        if action.iter().any(|v| !v.is_finite()) {
            return Err(fail(self.step, format!("action {action:?}")));
        }
        self.osc.step(&mut self.data, action, &mut self.shown);
        self.step += 1;
        let bad =
            |what: &str, v: &[f64]| v.iter().position(|x| !x.is_finite()).map(|i| format!("{what}[{i}]"));
        if let Some(detail) = bad("qpos", self.data.qpos()).or_else(|| bad("qvel", self.data.qvel())) {
            return Err(fail(self.step, detail));
        }
        // MuJoCo resets the data itself when qpos, qvel or qacc go NaN or huge ("the
        // simulation is unstable"), so a finite state alone proves nothing: its
        // warning counters (mjWARN_BADQPOS/BADQVEL/BADQACC) say it happened.
        let warnings = &self.data.ffi().warning;
        for (i, what) in [(3, "qpos"), (4, "qvel"), (5, "qacc")] {
            if warnings[i].number > 0 {
                return Err(fail(
                    self.step,
                    format!("MuJoCo reported a bad {what} (an unstable simulation) and reset it"),
                ));
            }
        }
        Ok(())
    }

    /// The object's body position, m.
    pub fn object_pos(&self) -> [f64; 3] {
        self.data.xpos()[self.object]
    }

    /// The object's orientation (w, x, y, z).
    pub fn object_quat(&self) -> [f64; 4] {
        self.data.xquat()[self.object]
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

    /// The `robot0_right_hand` body's orientation (w, x, y, z), as MuJoCo gives it.
    pub fn hand_quat(&self) -> [f64; 4] {
        self.data.xquat()[self.hand]
    }

    /// The finger joints, m (open: ±0.04).
    pub fn fingers(&self) -> [f64; 2] {
        self.osc.index().finger_qpos.map(|a| self.data.qpos()[a])
    }

    /// The arm's joints, rad.
    pub fn arm_q(&self) -> [f64; 7] {
        self.osc.index().arm_qpos.map(|a| self.data.qpos()[a])
    }

    /// The state row: the object's pose (7), then [`ROBOT_COLUMNS`].
    pub fn state(&self) -> Vec<f64> {
        let mut s = Vec::with_capacity(7 + ROBOT_COLUMNS.len());
        s.extend(self.object_pos());
        s.extend(self.object_quat());
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
    ///
    /// With render workers running ([`super::render_pool::start`]) a worker renders
    /// it, the same bytes, so that several threads render at once.
    ///
    /// With a render size ([`ArmEpisode::with_render_size`]) the camera renders at that side
    /// and the frame is upsampled to `size` as PyTorch's bilinear interpolation does.
    pub fn render(&mut self, size: usize) -> Result<Vec<u8>, ScenarioError> {
        self.render_native(size).map(|(frame, _)| frame)
    }

    /// [`Self::render`], and the camera's own frame at the render size where that is not
    /// `size` (the bytes the frame was upsampled from; `None` when rendered at `size`).
    ///
    /// # Errors
    /// As [`Self::render`].
    pub fn render_native(&mut self, size: usize) -> Result<(Vec<u8>, Option<Vec<u8>>), ScenarioError> {
        let side = self.render_from.unwrap_or(size);
        let raw = match (super::render_pool::active(), &self.key) {
            (true, Some(key)) => super::render_pool::render(key, &self.shown, side)?,
            _ => super::renderer::render_agentview(&mut self.data, side)?,
        };
        if side == size {
            return Ok((raw, None));
        }
        let frame =
            harness::resize::resize_bilinear_torch_u8(&raw, side, side, 3, size, size).ok_or_else(|| {
                ScenarioError::Render { message: format!("a {side}² frame that is not {side}² RGB") }
            })?;
        Ok((frame, Some(raw)))
    }

    /// The side frames are rendered at before resizing ([`Self::with_render_size`]), if any.
    pub fn render_size(&self) -> Option<usize> {
        self.render_from
    }

    /// Renders frames at `side` and upsamples them to the asked size (`None`: render at it).
    #[must_use]
    pub fn with_render_size(mut self, side: Option<usize>) -> Self {
        self.render_from = side;
        self
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
