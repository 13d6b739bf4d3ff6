//! The Push-T expert: a sampling planner that imagines candidate pushes in MuJoCo.
//!
//! At each decision the expert lists pushes at points spread along the T's
//! outline (push direction = the inward edge normal, tilted by a few angles;
//! several lengths), simulates each one in a private copy of the simulator from
//! the current block pose, and picks the push with the best reduction of the pose
//! error per control step spent (approach included). It then walks a collision-
//! free path to the push's start point (grid A*, [`super::path`]) and executes the
//! push. It replans after every push, and as soon as the block moves during an
//! approach. Privileged state is used throughout; this is a data-collection and
//! reference behaviour, not a learned policy.

use std::collections::VecDeque;
use std::sync::Arc;

use mujoco_rs::prelude::MjModel;

use super::geometry::{Pose2, TShape, coverage, wrap_angle};
use super::path::PathPlanner;
use super::physics::{PushTPhysics, PushTState};
use super::{PushTConfig, PushTEnv};

/// World units of pose error per radian of orientation error.
const ANGLE_WEIGHT: f64 = 70.0;
/// Control steps to wait after a replan that found no improving push.
const REPLAN_COOLDOWN: u32 = 5;
/// World units of cost per unit of missing coverage.
const COVERAGE_WEIGHT: f64 = 100.0;
/// Spacing of push points along the T's outline (world units).
const POINT_SPACING: f64 = 12.0;
/// Tilts of the push direction away from the inward normal (radians).
const TILTS: [f64; 3] = [-0.5, 0.0, 0.5];
/// Push lengths (world units), from fine adjustments to long shoves.
const LENGTHS: [f64; 5] = [3.0, 8.0, 18.0, 40.0, 80.0];
/// Target speed during a push (world units per control step).
const PUSH_SPEED: f64 = 12.0;
/// Gap between the agent's disk and the T at a push's start (world units).
const STANDOFF: f64 = 4.0;
/// Clearance margin of approach paths beyond the agent radius (world units).
const PATH_MARGIN: f64 = 7.0;
/// Control steps an approach is assumed to cost per world unit travelled.
const STEPS_PER_UNIT: f64 = 1.0 / 25.0;

/// Pose error: distance plus weighted angle difference (world units).
pub fn pose_error(block: &Pose2, goal: &Pose2) -> f64 {
    (block.x - goal.x).hypot(block.y - goal.y) + ANGLE_WEIGHT * wrap_angle(block.theta - goal.theta).abs()
}

/// The planner's cost: pose error far from the goal, plus missing coverage
/// (which is what the task scores) to steer the last few units.
fn cost(shape: &TShape, block: &Pose2, goal: &Pose2) -> f64 {
    pose_error(block, goal) + COVERAGE_WEIGHT * (1.0 - coverage(shape, block, goal))
}

/// A candidate push: start point, direction and length.
#[derive(Clone, Copy, Debug)]
struct Push {
    start: [f64; 2],
    dir: [f64; 2],
    length: f64,
}

impl Push {
    /// The targets of the push, one per control step (overshooting the length a little
    /// so that the lagging PD agent covers it).
    fn targets(&self) -> Vec<[f64; 2]> {
        let steps = (self.length / PUSH_SPEED).ceil().max(1.0) as usize;
        (1..=steps + 1)
            .map(|k| {
                let d = (k as f64 * PUSH_SPEED).min(self.length) + 0.25 * self.length.min(PUSH_SPEED);
                [self.start[0] + self.dir[0] * d, self.start[1] + self.dir[1] * d]
            })
            .collect()
    }
}

enum Phase {
    /// Walking to the start of `push` through `waypoints`.
    Approach { waypoints: VecDeque<[f64; 2]>, push: Push, planned_for: Pose2 },
    /// Executing the push's targets.
    Push { targets: VecDeque<[f64; 2]>, dir: [f64; 2] },
    /// Backing away from the block after a push.
    Retreat { target: [f64; 2], steps_left: u32 },
    /// Nothing planned.
    Idle,
}

/// The scripted Push-T expert.
pub struct Expert {
    sim: PushTPhysics,
    cfg: PushTConfig,
    phase: Phase,
    last_target: Option<[f64; 2]>,
    cooldown: u32,
    /// Pose to push the block to instead of the episode's goal (see [`Expert::set_target`]).
    target: Option<Pose2>,
}

impl Expert {
    /// An expert that imagines with its own simulator on `model`.
    pub fn new(model: Arc<MjModel>, cfg: &PushTConfig) -> Self {
        Self {
            sim: PushTPhysics::new(model, cfg),
            cfg: cfg.clone(),
            phase: Phase::Idle,
            last_target: None,
            cooldown: 0,
            target: None,
        }
    }

    /// Pushes the block to `target` instead of the episode's goal (`None`: the goal
    /// again). Drops the current plan, so the next action replans.
    pub fn set_target(&mut self, target: Option<Pose2>) {
        self.target = target;
        self.phase = Phase::Idle;
        self.cooldown = 0;
    }

    /// The next action (the agent's absolute target position).
    pub fn act(&mut self, env: &PushTEnv) -> [f64; 2] {
        let state = env.state();
        let goal = self.target.unwrap_or_else(|| env.goal());
        if let Some(a) = self.advance(&state) {
            self.last_target = Some(a);
            return a;
        }
        // Replanning costs a few hundred imagined pushes: after one that found no
        // improving push, wait a few steps (the agent holds still) before the next.
        if self.cooldown > 0 {
            self.cooldown -= 1;
        } else {
            self.replan(&state, &goal);
            if let Some(a) = self.advance(&state) {
                self.last_target = Some(a);
                return a;
            }
            self.cooldown = REPLAN_COOLDOWN;
        }
        self.last_target.unwrap_or(state.agent)
    }

    /// Continues the current phase; `None` when it is over (or invalidated).
    fn advance(&mut self, state: &PushTState) -> Option<[f64; 2]> {
        match &mut self.phase {
            Phase::Idle => None,
            Phase::Approach { waypoints, push, planned_for } => {
                let moved = (state.block.x - planned_for.x).hypot(state.block.y - planned_for.y)
                    + ANGLE_WEIGHT * wrap_angle(state.block.theta - planned_for.theta).abs();
                if moved > 1.5 {
                    self.phase = Phase::Idle;
                    return None;
                }
                let a = state.agent;
                while let Some(w) = waypoints.front().copied() {
                    let d = (w[0] - a[0]).hypot(w[1] - a[1]);
                    let speed = state.agent_vel[0].hypot(state.agent_vel[1]);
                    let last = waypoints.len() == 1;
                    if (last && d < 3.0 && speed < 40.0) || (!last && d < 12.0) {
                        waypoints.pop_front();
                    } else {
                        return Some(w);
                    }
                }
                let targets: VecDeque<[f64; 2]> = push.targets().into();
                self.phase = Phase::Push { targets, dir: push.dir };
                self.advance(state)
            }
            Phase::Push { targets, dir } => match targets.pop_front() {
                Some(t) => Some(t),
                None => {
                    // Back off along the push direction so the next approach starts free.
                    let (d, a) = (*dir, state.agent);
                    let back = [a[0] - d[0] * 10.0, a[1] - d[1] * 10.0];
                    self.phase = Phase::Retreat { target: back, steps_left: 1 };
                    Some(back)
                }
            },
            Phase::Retreat { target, steps_left } => {
                if *steps_left == 0 {
                    self.phase = Phase::Idle;
                    return None;
                }
                *steps_left -= 1;
                Some(*target)
            }
        }
    }

    /// Chooses the next push by imagining every candidate.
    fn replan(&mut self, state: &PushTState, goal: &Pose2) {
        let shape = self.cfg.shape();
        let r = self.cfg.agent.radius;
        let planner = PathPlanner {
            shape: &shape,
            block: state.block,
            clearance: r + PATH_MARGIN,
            world: self.cfg.world.size,
        };
        let now = cost(&shape, &state.block, goal);
        let mut best: Option<(f64, Push, Vec<[f64; 2]>)> = None;
        for (point, normal) in outline_points(&shape, POINT_SPACING) {
            let p = state.block.apply(point);
            let n = rotate(normal, state.block.theta);
            let start = [p[0] + n[0] * (r + STANDOFF), p[1] + n[1] * (r + STANDOFF)];
            let size = self.cfg.world.size;
            if !(0.0..=size).contains(&start[0]) || !(0.0..=size).contains(&start[1]) {
                continue;
            }
            if shape.distance(state.block.inverse_apply(start)) < r + 1.0 {
                continue;
            }
            let Some(path) = planner.plan(state.agent, start) else {
                continue;
            };
            let approach_len: f64 = path_length(state.agent, &path);
            for tilt in TILTS {
                let dir = rotate([-n[0], -n[1]], tilt);
                for length in LENGTHS {
                    let push = Push { start, dir, length };
                    let Some(after) = self.imagine(state, &push) else {
                        continue;
                    };
                    let gain = now - cost(&shape, &after, goal);
                    let steps = approach_len * STEPS_PER_UNIT + push.targets().len() as f64 + 2.0;
                    let rate = gain / steps;
                    if best.as_ref().is_none_or(|(b, _, _)| rate > *b) {
                        best = Some((rate, push, path.clone()));
                    }
                }
            }
        }
        self.phase = match best {
            Some((rate, push, path)) if rate > 0.0 => {
                Phase::Approach { waypoints: path.into(), push, planned_for: state.block }
            }
            _ => Phase::Idle,
        };
    }

    /// The block pose after executing `push` from its start point with the agent at
    /// rest, or `None` if the imagined simulation diverged.
    fn imagine(&mut self, state: &PushTState, push: &Push) -> Option<Pose2> {
        self.sim.set_state(&PushTState { agent: push.start, agent_vel: [0.0; 2], block: state.block });
        for t in push.targets() {
            self.sim.control_step(t);
        }
        // One more step at rest so the block settles (it is damped: it stops at once).
        self.sim.control_step(self.sim.state().agent);
        self.sim.divergence().is_none().then(|| self.sim.state().block)
    }
}

fn path_length(from: [f64; 2], path: &[[f64; 2]]) -> f64 {
    let mut len = 0.0;
    let mut a = from;
    for b in path {
        len += (b[0] - a[0]).hypot(b[1] - a[1]);
        a = *b;
    }
    len
}

fn rotate(v: [f64; 2], theta: f64) -> [f64; 2] {
    let (s, c) = theta.sin_cos();
    [v[0] * c - v[1] * s, v[0] * s + v[1] * c]
}

/// Points along the T's outline (body frame) with their outward normals, spaced about
/// `spacing` apart, excluding corners.
fn outline_points(shape: &super::geometry::TShape, spacing: f64) -> Vec<([f64; 2], [f64; 2])> {
    let v = shape.outline();
    let area = super::geometry::signed_area(&v);
    let mut out = Vec::new();
    for i in 0..v.len() {
        let (a, b) = (v[i], v[(i + 1) % v.len()]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len = dx.hypot(dy);
        // Outward normal: right of the edge for a counter-clockwise (positive area) polygon.
        let n = if area > 0.0 { [dy / len, -dx / len] } else { [-dy / len, dx / len] };
        let k = (len / spacing).floor().max(1.0) as usize;
        for j in 0..k {
            let t = (j as f64 + 0.5) / k as f64;
            out.push(([a[0] + t * dx, a[1] + t * dy], n));
        }
    }
    out
}
