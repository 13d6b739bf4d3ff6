//! A scripted Lift expert that reads privileged state (the cube's pose), and the
//! ways it can be made to fail as weak policies fail, for world-model data.
//!
//! The expert is a waypoint follower in robomimic's action space: it aligns the
//! gripper's yaw with the cube (modulo a quarter turn: the cube is square), goes
//! above it with the gripper open, descends, closes, waits for the fingers and
//! lifts. Each action is the clipped proportional step toward the current
//! waypoint, in units of the controller's 0.05 m / 0.5 rad limits.

use crate::robosuite::episode::ArmEpisode;
use crate::robosuite::linalg::Mat;
use crate::robosuite::osc::{orientation_error, pointing_down, servo_action};

/// How the scripted behaviour departs from the expert.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LiftFlaws {
    /// Aim this far (m) beside the cube along the gripper's closing axis: a
    /// miss of more than the finger reach (about 0.02 m) grasps nothing.
    pub aim_offset: f64,
    /// Stop and open the gripper once the cube has risen this far (m) in the
    /// lift, short of the 0.04 m that counts as success (a drop); 0 never.
    pub drop_height: f64,
    /// Steps of standing still before each phase (hesitation).
    pub hesitate: u32,
    /// Instead of grasping, come down beside the cube with the gripper closed
    /// and shove it across the table.
    pub push: bool,
}

/// The expert's phases.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Above,
    Descend,
    Close,
    Lift,
}

/// A stateful scripted Lift behaviour.
#[derive(Clone, Debug)]
pub struct LiftExpert {
    flaws: LiftFlaws,
    phase: Phase,
    phase_steps: u32,
    held: u32,
    /// The cube's height when the lift began.
    lift_from: f64,
    /// Whether a drop has begun (it stays begun).
    dropping: bool,
}

/// Height of the approach waypoint above the cube's centre, m.
const ABOVE: f64 = 0.08;
/// How far down the fingers reach past the grip site to centre on the cube, m.
const GRASP_DEPTH: f64 = 0.0;
/// Steps the gripper takes to close from fully open (1 / 0.2 × 2) plus settling.
const CLOSE_STEPS: u32 = 12;
/// How far beside the cube's centre a push starts, m.
const PUSH_SIDE: f64 = 0.06;
/// Lift this high above the start, m.
const LIFT_TO: f64 = 0.15;

impl LiftExpert {
    /// A behaviour with the given flaws (the default has none).
    pub fn new(flaws: LiftFlaws) -> Self {
        Self { flaws, phase: Phase::Above, phase_steps: 0, held: 0, lift_from: 0.0, dropping: false }
    }

    fn next(&mut self, p: Phase) {
        self.phase = p;
        self.phase_steps = 0;
        self.held = 0;
    }

    /// The action for the episode's current state.
    pub fn act(&mut self, ep: &ArmEpisode) -> [f64; 7] {
        let cube = ep.object_pos();
        let eef = ep.eef_pos();
        let target_ori = grasp_orientation(&ep.eef_mat(), ep.object_quat());
        // The closing axis is the gripper's y axis (the second column).
        let side = [target_ori[0][1], target_ori[1][1], target_ori[2][1]];
        let offset = if self.flaws.push { -PUSH_SIDE } else { self.flaws.aim_offset };
        let aim = [cube[0] + side[0] * offset, cube[1] + side[1] * offset, cube[2]];
        self.phase_steps += 1;
        if self.held < self.flaws.hesitate {
            self.held += 1;
            let g = if matches!(self.phase, Phase::Close | Phase::Lift) { 1.0 } else { -1.0 };
            return [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, g];
        }
        // A push comes down with the gripper already closed.
        let open = if self.flaws.push { 1.0 } else { -1.0 };
        let (target, grip) = match self.phase {
            Phase::Above => ([aim[0], aim[1], aim[2] + ABOVE], open),
            Phase::Descend => ([aim[0], aim[1], aim[2] - GRASP_DEPTH], open),
            // Pushing: aim through the cube at its far side, whatever it has moved to.
            Phase::Close if self.flaws.push => {
                ([cube[0] + side[0] * PUSH_SIDE, cube[1] + side[1] * PUSH_SIDE, cube[2]], 1.0)
            }
            Phase::Close => ([aim[0], aim[1], aim[2] - GRASP_DEPTH], 1.0),
            Phase::Lift => {
                if self.phase_steps == 1 {
                    self.lift_from = cube[2];
                }
                let risen = cube[2] - self.lift_from;
                self.dropping |= self.flaws.drop_height > 0.0 && risen > self.flaws.drop_height;
                if self.dropping {
                    (eef, -1.0)
                } else if self.flaws.drop_height > 0.0 {
                    // A hesitant lift, about 0.6 cm a step, so the drop comes before success.
                    ([eef[0], eef[1], eef[2] + 0.0125], 1.0)
                } else {
                    ([eef[0], eef[1], self.lift_from + LIFT_TO], 1.0)
                }
            }
        };
        let err = [target[0] - eef[0], target[1] - eef[1], target[2] - eef[2]];
        let dist = (err[0] * err[0] + err[1] * err[1] + err[2] * err[2]).sqrt();
        let rot = orientation_error(&target_ori, &ep.eef_mat());
        let rot_err = (rot[0] * rot[0] + rot[1] * rot[1] + rot[2] * rot[2]).sqrt();
        match self.phase {
            Phase::Above if dist < 0.01 && rot_err < 0.05 => self.next(Phase::Descend),
            Phase::Descend if dist < 0.008 => self.next(Phase::Close),
            Phase::Close if self.phase_steps >= CLOSE_STEPS && !self.flaws.push => self.next(Phase::Lift),
            _ => {}
        }
        servo_action(err, rot, grip)
    }
}

/// The grip orientation for a cube: pointing straight down, the gripper's x axis
/// along a cube face, picking the face nearest the current yaw (the cube looks
/// the same every quarter turn).
pub fn grasp_orientation(current: &Mat<3, 3>, cube_quat: [f64; 4]) -> Mat<3, 3> {
    let [w, x, y, z] = cube_quat;
    // The cube's x axis in the world: the first column of its rotation matrix.
    let cube_yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
    let cur_yaw = current[1][0].atan2(current[0][0]);
    let quarter = std::f64::consts::FRAC_PI_2;
    let k = ((cur_yaw - cube_yaw) / quarter).round();
    pointing_down(cube_yaw + k * quarter)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_grasp_orientation_is_a_rotation_pointing_down_at_the_nearest_face() {
        let ident = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];
        // A cube turned 100° about z: its faces are at 100° − 90° = 10° from the
        // current yaw of 0, so the grasp yaw is 10°.
        let t = 100f64.to_radians();
        let r = grasp_orientation(&ident, [(t / 2.0).cos(), 0.0, 0.0, (t / 2.0).sin()]);
        let yaw = r[1][0].atan2(r[0][0]).to_degrees();
        assert!((yaw - 10.0).abs() < 1e-9, "{yaw}");
        // Determinant +1: c·(−c)·(−1) − s·(s·(−1)) = c² + s² = 1.
        let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
            - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
        assert!((det - 1.0).abs() < 1e-12);
        assert_eq!(r[2][2], -1.0, "z axis points down");
    }
}
