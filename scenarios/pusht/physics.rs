//! The Push-T reference simulator: a planar MuJoCo model stepped at the control rate.
//!
//! The scene is generated from [`PushTConfig`]: the T block is two boxes on
//! slide-x / slide-y / hinge-z joints with strong joint damping (quasi-static
//! pushing: the block stops when contact stops), the agent is a vertical capsule
//! on two slide joints whose velocity is set every physics step by gym-pusht's PD
//! law `v += (kp (target - p) - kd v) dt`, walls are static boxes that collide with
//! the block only (the agent is kinematic in pymunk and passes over walls).
//! All contacts are frictionless (condim 1), as pymunk's default shape friction is 0.
//! Coordinates are the 512 x 512 world units used by gym-pusht, GPC and
//! diffusion_policy; MuJoCo is unit-agnostic, so no scaling is needed.

use std::sync::Arc;

use mujoco_rs::prelude::*;

use super::colors;
use super::config::PushTConfig;
use super::geometry::{Pose2, Rect, wrap_angle};
use crate::error::ScenarioError;

/// Indices into qpos / qvel: agent x, y then block x, y, theta (the MJCF's body order).
const AGENT_X: usize = 0;
const AGENT_Y: usize = 1;
const BLOCK_X: usize = 2;
const BLOCK_Y: usize = 3;
const BLOCK_T: usize = 4;
/// Agent speeds above this (world units / s, ~100 world widths a second) mean the PD law blew up.
const MAX_AGENT_SPEED: f64 = 5.0e4;

/// The full simulator state needed to reproduce an episode from here.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PushTState {
    /// Agent centre (world units).
    pub agent: [f64; 2],
    /// The PD law's agent velocity (world units / s).
    pub agent_vel: [f64; 2],
    /// Block pose.
    pub block: Pose2,
}

/// Builds the MJCF text of the scene from the parameters.
///
/// Besides the bodies that take part in the dynamics the scene holds render-only
/// elements for MuJoCo's own renderer (the `--renderer mujoco` cross-check): a
/// white floor, the goal T on a mocap body, the block's outline and fill, the
/// agent's inner disk, thin walls and a top-down orthographic camera. They have
/// `contype = conaffinity = 0` and no mass, so they change nothing in the physics.
pub fn mjcf(cfg: &PushTConfig) -> String {
    let b = &cfg.block;
    let a = &cfg.agent;
    let timestep = cfg.physics_dt() / f64::from(cfg.timing.mujoco_substeps);
    let damp_lin = b.mass / b.damping_time;
    let damp_rot = b.inertia / b.damping_time;
    // Half-height of the planar slab every colliding geom lives in.
    let h = 10.0;
    let (fill, edge) = (rgb(colors::BLOCK), rgb(colors::BLOCK_EDGE));
    // A visual-only box over `r` grown by `grow` (negative shrinks), its top face at `top`.
    let vbox = |r: &Rect, grow: [f64; 4], top: f64, color: &str| {
        let (x0, x1, y0, y1) = (r.x[0] - grow[0], r.x[1] + grow[1], r.y[0] - grow[2], r.y[1] + grow[3]);
        format!(
            r#"<geom type="box" pos="{} {} {}" size="{} {} 0.25" contype="0" conaffinity="0" mass="0" rgba="{color}"/>"#,
            (x0 + x1) / 2.0,
            (y0 + y1) / 2.0,
            top - 0.25,
            (x1 - x0) / 2.0,
            (y1 - y0) / 2.0
        )
    };
    let e = 2.0; // half width of the outline, as in the rasteriser
    // Collision boxes (edge colour), an outer ring under them and an inner fill above.
    // The stem's fill reaches into the bar so the junction shows no seam.
    let part = |name: &str, r: &Rect| {
        let [cx, cy] = r.centre();
        let [hx, hy] = r.half();
        format!(
            r#"<geom name="{name}" type="box" pos="{cx} {cy} 0" size="{hx} {hy} {h}" contype="3" conaffinity="3" condim="1" rgba="{edge}"/>
      {ring}"#,
            ring = vbox(r, [e; 4], h - 0.5, &edge)
        )
    };
    let fills = format!(
        "{}\n      {}",
        vbox(&b.bar, [-e, -e, -e, -e], h + 0.5, &fill),
        vbox(&b.stem, [-e, -e, e, -e], h + 0.5, &fill)
    );
    let goal_geoms =
        [&b.bar, &b.stem].map(|r| vbox(r, [0.0; 4], -h + 1.0, &rgb(colors::GOAL))).join("\n      ");
    let s = cfg.world.size;
    let walls = walls(cfg, h);
    let inertia = b.inertia;
    let off = cfg.render.size.max(512);
    format!(
        r#"<mujoco model="pusht">
  <option timestep="{timestep}" gravity="0 0 0" integrator="implicitfast" cone="pyramidal"/>
  <statistic extent="{s}" center="{c} {c} 0"/>
  <visual>
    <global offwidth="{off}" offheight="{off}"/>
    <headlight ambient="1 1 1" diffuse="0 0 0" specular="0 0 0"/>
    <map znear="0.01" zfar="10"/>
  </visual>
  <worldbody>
    <camera name="top" pos="{c} {c} {cam_z}" xyaxes="1 0 0 0 1 0" projection="orthographic" fovy="90"/>
    <geom name="floor" type="plane" pos="{c} {c} {floor_z}" size="{c} {c} 1" contype="0" conaffinity="0" rgba="1 1 1 1"/>
    {walls}
    <body name="goal" mocap="true">
      {goal_geoms}
    </body>
    <body name="agent" pos="0 0 0">
      <joint name="agent_x" type="slide" axis="1 0 0"/>
      <joint name="agent_y" type="slide" axis="0 1 0"/>
      <geom name="agent" type="capsule" fromto="0 0 -5 0 0 5" size="{radius}" mass="{amass}" contype="1" conaffinity="1" condim="1" rgba="{agent_rgba}"/>
      <geom type="cylinder" pos="0 0 {inner_z}" size="{inner} 0.25" contype="0" conaffinity="0" mass="0" rgba="{inner_rgba}"/>
    </body>
    <body name="block" pos="0 0 0">
      <joint name="block_x" type="slide" axis="1 0 0" damping="{damp_lin}"/>
      <joint name="block_y" type="slide" axis="0 1 0" damping="{damp_lin}"/>
      <joint name="block_theta" type="hinge" axis="0 0 1" damping="{damp_rot}"/>
      <inertial pos="0 0 0" mass="{mass}" diaginertia="{inertia} {inertia} {inertia}"/>
      {bar}
      {stem}
      {fills}
    </body>
  </worldbody>
</mujoco>
"#,
        c = s / 2.0,
        cam_z = 2.0 * s,
        floor_z = -h - 1.0,
        mass = b.mass,
        bar = part("bar", &b.bar),
        stem = part("stem", &b.stem),
        radius = a.radius,
        amass = a.mass,
        agent_rgba = rgb(colors::AGENT),
        inner = colors::AGENT_INNER_RADIUS,
        inner_z = 5.0 + a.radius + 0.5,
        inner_rgba = rgb(colors::AGENT_INNER),
    )
}

/// The `rgba` attribute of an opaque colour.
fn rgb(c: [u8; 3]) -> String {
    format!("{} {} {} 1", f64::from(c[0]) / 255.0, f64::from(c[1]) / 255.0, f64::from(c[2]) / 255.0)
}

/// The four colliding walls (invisible, alpha 0) and the thin visual walls that mark their
/// segments, for a slab of half-height `h`.
fn walls(cfg: &PushTConfig, h: f64) -> String {
    let s = cfg.world.size;
    let lo = cfg.world.wall_inset + cfg.world.wall_radius;
    let hi = s - 1.0 - cfg.world.wall_inset - cfg.world.wall_radius;
    let thick = 20.0;
    let mid = (lo + hi) / 2.0;
    let half_len = (hi - lo) / 2.0 + 2.0 * thick;
    // Colliding walls are invisible (alpha 0); thin visual walls mark the segments.
    let wall = |name: &str, x: f64, y: f64, hx: f64, hy: f64| {
        format!(
            r#"<geom name="{name}" type="box" pos="{x} {y} 0" size="{hx} {hy} {h}" contype="2" conaffinity="2" condim="1" rgba="0 0 0 0"/>"#
        )
    };
    let (wl, wh, wr) = (cfg.world.wall_inset, s - 1.0 - cfg.world.wall_inset, cfg.world.wall_radius);
    let wall_rgba = rgb(colors::WALL);
    let vwall = |x: f64, y: f64, hx: f64, hy: f64| {
        format!(
            r#"<geom type="box" pos="{x} {y} {}" size="{hx} {hy} 0.25" contype="0" conaffinity="0" mass="0" rgba="{wall_rgba}"/>"#,
            -h + 0.5
        )
    };
    let wmid = (wl + wh) / 2.0;
    let wlen = (wh - wl) / 2.0 + wr;
    [
        wall("wall_left", lo - thick, mid, thick, half_len),
        wall("wall_right", hi + thick, mid, thick, half_len),
        wall("wall_top", mid, lo - thick, half_len, thick),
        wall("wall_bottom", mid, hi + thick, half_len, thick),
        vwall(wl, wmid, wr, wlen),
        vwall(wh, wmid, wr, wlen),
        vwall(wmid, wl, wlen, wr),
        vwall(wmid, wh, wlen, wr),
    ]
    .join("\n    ")
}

/// A Push-T episode in MuJoCo: the model, its data and the PD velocity.
pub struct PushTPhysics {
    data: MjData<Arc<MjModel>>,
    agent_vel: [f64; 2],
    kp: f64,
    kd: f64,
    dt: f64,
    substeps: u32,
    physics_per_control: u32,
    world_size: f64,
}

impl PushTPhysics {
    /// Compiles the MuJoCo model of the scene.
    ///
    /// # Errors
    /// [`ScenarioError::Model`] if MuJoCo rejects the generated MJCF.
    pub fn compile(cfg: &PushTConfig) -> Result<Arc<MjModel>, ScenarioError> {
        let mut model = MjModel::from_xml_string(&mjcf(cfg))
            .map_err(|e| ScenarioError::Model { scenario: "pusht".into(), message: e.to_string() })?;
        // An orthographic camera's fovy is a length, but the XML compiler caps it like an
        // angle (< 180), so the top camera gets the world's side here.
        model.cam_fovy_mut()[0] = cfg.world.size;
        Ok(Arc::new(model))
    }

    /// A simulator on a compiled model (cheap: the model is shared).
    pub fn new(model: Arc<MjModel>, cfg: &PushTConfig) -> Self {
        Self {
            data: MjData::new(model),
            agent_vel: [0.0; 2],
            kp: cfg.agent.kp,
            kd: cfg.agent.kd,
            dt: cfg.physics_dt(),
            substeps: cfg.timing.mujoco_substeps,
            physics_per_control: cfg.physics_per_control(),
            world_size: cfg.world.size,
        }
    }

    /// Sets the full state (block angle before position, as the GPC reset does),
    /// zeroes the block's velocity and recomputes derived quantities.
    pub fn set_state(&mut self, s: &PushTState) {
        self.data.reset();
        {
            let qpos = self.data.qpos_mut();
            qpos[BLOCK_T] = s.block.theta;
            qpos[BLOCK_X] = s.block.x;
            qpos[BLOCK_Y] = s.block.y;
            qpos[AGENT_X] = s.agent[0];
            qpos[AGENT_Y] = s.agent[1];
        }
        self.data.qvel_mut().fill(0.0);
        self.agent_vel = s.agent_vel;
        self.data.forward();
    }

    /// The current state (block angle wrapped into (-π, π]).
    pub fn state(&self) -> PushTState {
        let q = self.data.qpos();
        PushTState {
            agent: [q[AGENT_X], q[AGENT_Y]],
            agent_vel: self.agent_vel,
            block: Pose2::new(q[BLOCK_X], q[BLOCK_Y], wrap_angle(q[BLOCK_T])),
        }
    }

    /// Advances one physics step (1 / physics_hz s) towards `target`.
    pub fn physics_step(&mut self, target: [f64; 2]) {
        let q = self.data.qpos();
        let p = [q[AGENT_X], q[AGENT_Y]];
        for i in 0..2 {
            self.agent_vel[i] += (self.kp * (target[i] - p[i]) - self.kd * self.agent_vel[i]) * self.dt;
        }
        for _ in 0..self.substeps {
            let v = self.data.qvel_mut();
            v[AGENT_X] = self.agent_vel[0];
            v[AGENT_Y] = self.agent_vel[1];
            self.data.step();
        }
    }

    /// Advances one control step (physics_hz / control_hz physics steps) towards `target`,
    /// which is clipped to the world square.
    pub fn control_step(&mut self, target: [f64; 2]) {
        let t = target.map(|v| v.clamp(0.0, self.world_size));
        for _ in 0..self.physics_per_control {
            self.physics_step(t);
        }
    }

    /// Describes the first sign of a diverging simulation, if any: a non-finite
    /// or runaway PD velocity, a position outside the world, or MuJoCo's own
    /// bad-state warnings (MuJoCo silently resets the data when qpos, qvel or
    /// qacc become NaN or huge, so a finite state alone proves nothing).
    pub fn divergence(&self) -> Option<String> {
        let v = self.agent_vel;
        if !(v[0].is_finite() && v[1].is_finite()) || v[0].hypot(v[1]) > MAX_AGENT_SPEED {
            return Some(format!("agent PD velocity {v:?}"));
        }
        let warnings = &self.data.ffi().warning;
        for (i, what) in [(3, "qpos"), (4, "qvel"), (5, "qacc")] {
            if warnings[i].number > 0 {
                return Some(format!("MuJoCo reported a bad {what} and reset the simulation"));
            }
        }
        let q = self.data.qpos();
        let qv = self.data.qvel();
        let names = ["agent_x", "agent_y", "block_x", "block_y", "block_theta"];
        for (i, name) in names.iter().enumerate() {
            if !q[i].is_finite() || !qv[i].is_finite() {
                return Some(format!("{name}: qpos {} qvel {}", q[i], qv[i]));
            }
        }
        let margin = self.world_size;
        for (i, name) in names.iter().enumerate().take(4) {
            if q[i] < -margin || q[i] > 2.0 * margin {
                return Some(format!("{name} = {} left the world", q[i]));
            }
        }
        None
    }
}
