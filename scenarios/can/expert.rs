//! A scripted Can expert that reads privileged state (the can's position), and
//! the ways it can be made to fail, for world-model data.
//!
//! The expert grasps the can from above with the gripper pointing down (the can
//! is round, so the yaw is kept), lifts it over the bins' walls, carries it over
//! its target quadrant of bin 2, lowers it, lets go and withdraws upward (the
//! success check wants the gripper away from the can).

use crate::robosuite::episode::ArmEpisode;
use crate::robosuite::linalg::Mat;
use crate::robosuite::osc::{orientation_error, pointing_down, servo_action};

/// How the scripted behaviour departs from the expert.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CanFlaws {
    /// Aim this far (m) beside the can along the gripper's closing axis: a miss.
    pub aim_offset: f64,
    /// Open the gripper while carrying, this far (m, along y) short of the
    /// target quadrant's centre (a drop on the way); 0 never.
    pub drop_short: f64,
    /// Carry to the wrong quadrant of bin 2 (bread's, next to the can's).
    pub wrong_bin: bool,
    /// Steps of standing still before each phase (hesitation).
    pub hesitate: u32,
    /// Instead of grasping, come down beside the can with the gripper closed and
    /// shove it across bin 1 (it tips or slides; it never reaches bin 2).
    pub push: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Above,
    Descend,
    Close,
    Lift,
    Carry,
    Lower,
    Release,
    Withdraw,
}

/// A stateful scripted Can behaviour.
#[derive(Clone, Debug)]
pub struct CanExpert {
    flaws: CanFlaws,
    target: [f64; 2],
    phase: Phase,
    phase_steps: u32,
    held: u32,
    /// The orientation to hold: straight down, the yaw at the first step.
    down: Option<Mat<3, 3>>,
}

/// Approach height of the grip site over the can's origin, m.
const ABOVE: f64 = 0.10;
/// Grasp height of the grip site over the can's origin, m.
const GRASP_ABOVE: f64 = 0.02;
/// Carrying height of the grip site: the can hangs about 0.06 m below it and the bins' walls reach 0.9 m, m.
const CARRY_Z: f64 = 0.99;
/// Release height of the grip site over bin 2's reference height, m.
const RELEASE_Z: f64 = 0.10;
/// How far beside the can's axis a push starts, m.
const PUSH_SIDE: f64 = 0.07;
/// Steps to close (1 / 0.2 × 2, plus settling) and to open.
const GRIP_STEPS: u32 = 12;

impl CanExpert {
    /// A behaviour carrying to `target` (x, y) with the given flaws.
    pub fn new(target: [f64; 2], flaws: CanFlaws) -> Self {
        Self { flaws, target, phase: Phase::Above, phase_steps: 0, held: 0, down: None }
    }

    fn next(&mut self, p: Phase) {
        self.phase = p;
        self.phase_steps = 0;
        self.held = 0;
    }

    /// The action for the episode's current state; `bin_z` is bin 2's reference height.
    pub fn act(&mut self, ep: &ArmEpisode, bin_z: f64) -> [f64; 7] {
        let can = ep.object_pos();
        let eef = ep.eef_pos();
        let cur = ep.eef_mat();
        let down = *self.down.get_or_insert_with(|| pointing_down(cur[1][0].atan2(cur[0][0])));
        let side = [down[0][1], down[1][1]];
        let offset = if self.flaws.push { -PUSH_SIDE } else { self.flaws.aim_offset };
        let aim = [can[0] + side[0] * offset, can[1] + side[1] * offset];
        self.phase_steps += 1;
        let closed = matches!(self.phase, Phase::Close | Phase::Lift | Phase::Carry | Phase::Lower);
        if self.held < self.flaws.hesitate {
            self.held += 1;
            return [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, if closed { 1.0 } else { -1.0 }];
        }
        let goal = [self.target[0], self.target[1] - self.flaws.drop_short];
        // A push comes down with the gripper already closed.
        let open = if self.flaws.push { 1.0 } else { -1.0 };
        let (target, grip) = match self.phase {
            Phase::Above => ([aim[0], aim[1], can[2] + ABOVE], open),
            Phase::Descend => ([aim[0], aim[1], can[2] + GRASP_ABOVE], open),
            // Pushing: aim through the can at its far side, wherever it has moved to.
            Phase::Close if self.flaws.push => {
                ([can[0] + side[0] * PUSH_SIDE, can[1] + side[1] * PUSH_SIDE, can[2] + GRASP_ABOVE], 1.0)
            }
            Phase::Close => ([aim[0], aim[1], can[2] + GRASP_ABOVE], 1.0),
            Phase::Lift => ([eef[0], eef[1], CARRY_Z], 1.0),
            Phase::Carry => ([goal[0], goal[1], CARRY_Z], 1.0),
            Phase::Lower => ([goal[0], goal[1], bin_z + RELEASE_Z], 1.0),
            Phase::Release => ([eef[0], eef[1], eef[2]], -1.0),
            Phase::Withdraw => ([eef[0], eef[1], CARRY_Z], -1.0),
        };
        let err = [target[0] - eef[0], target[1] - eef[1], target[2] - eef[2]];
        let xy = (err[0] * err[0] + err[1] * err[1]).sqrt();
        let dist = (xy * xy + err[2] * err[2]).sqrt();
        let rot = orientation_error(&down, &cur);
        let rot_err = (rot[0] * rot[0] + rot[1] * rot[1] + rot[2] * rot[2]).sqrt();
        match self.phase {
            Phase::Above if dist < 0.006 && rot_err < 0.05 => self.next(Phase::Descend),
            // Contact with the can's rim can hold the fingers a few millimetres
            // short: close anyway once the descent has had its time.
            Phase::Descend if dist < 0.008 || self.phase_steps > 40 => self.next(Phase::Close),
            Phase::Close if self.phase_steps >= GRIP_STEPS && !self.flaws.push => self.next(Phase::Lift),
            Phase::Lift if err[2].abs() < 0.02 => self.next(Phase::Carry),
            // A drop on the way lets go as soon as the can is over the short goal.
            Phase::Carry if xy < 0.01 && self.flaws.drop_short > 0.0 => self.next(Phase::Release),
            Phase::Carry if xy < 0.01 => self.next(Phase::Lower),
            Phase::Lower if dist < 0.01 => self.next(Phase::Release),
            Phase::Release if self.phase_steps >= GRIP_STEPS => self.next(Phase::Withdraw),
            _ => {}
        }
        servo_action(err, rot, grip)
    }
}
