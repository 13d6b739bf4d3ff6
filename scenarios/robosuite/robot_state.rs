//! The robot state robomimic policies read (robosuite 1.5's proprioceptive observables), measured
//! in the simulator and dead-reckoned from the commands in imagination.
//!
//! robosuite names them `robot0_eef_pos` (the grip site's position, m), `robot0_eef_quat` (the
//! `robot0_right_hand` body's orientation, x y z w: robosuite ≤ 1.5 reads the body, not the
//! site, so the two disagree by the gripper's mounting rotation) and `robot0_gripper_qpos` (the
//! two finger joints, m). A world model imagines frames only, so the imagined branch estimates
//! them from what the episode showed at reset and the commands since ([`RobotEstimate`]): a
//! model of how the arm follows OSC_POSE's commands, fitted on scripted Lift episodes (each
//! step's displacement and rotation a damped response to the command; the fingers pulled
//! towards the servo targets of the gripper's running command). It does not see contacts: an
//! arm pushing on the table, or fingers closed on an object, drift from it, so a policy that
//! leans on the state can disagree between the branches for that reason
//! (`robot_state_estimate_along_expert_lift_episodes` measures by how much).

use harness::task::StateKey;

use super::episode::ArmEpisode;
use super::episode::mat_to_quat;
use super::osc::{MAX_DPOS, MAX_DROT, axis_angle_to_mat, grip_step, servo_target};

/// The keys, in the order of [`measured`] and [`RobotEstimate::vector`].
pub fn keys() -> Vec<StateKey> {
    vec![
        StateKey::new("robot0_eef_pos", 3),
        StateKey::new("robot0_eef_quat", 4),
        StateKey::new("robot0_gripper_qpos", 2),
    ]
}

/// The servo target of finger `i` (0: `finger_joint1`, range [0, 0.04] m; 1: `finger_joint2`,
/// [−0.04, 0]) for the gripper's running command `c` in [−1, 1], as the controller maps it.
pub(crate) fn finger_target(i: usize, c: f64) -> f64 {
    servo_target(if i == 0 { [0.0, FINGER_OPEN] } else { [-FINGER_OPEN, 0.0] }, c)
}

/// A finger joint's opening when the gripper is fully open, m (the Panda gripper's servo range).
const FINGER_OPEN: f64 = 0.04;

/// The measured state of an episode, as robosuite reports it.
pub fn measured(ep: &ArmEpisode) -> Vec<f32> {
    let [w, x, y, z] = ep.hand_quat();
    let mut v: Vec<f32> = ep.eef_pos().iter().map(|&p| p as f32).collect();
    v.extend([x, y, z, w].map(|c| c as f32));
    v.extend(ep.fingers().map(|f| f as f32));
    v
}

/// How the arm follows OSC_POSE's commands, per control step (least squares on the scripted
/// expert's Lift episodes of seeds 0–4, 120 steps each; `cargo test -p scenarios robot_state_fit
/// -- --ignored --nocapture`): the grip site's displacement `v' = POS_KEEP·v + POS_GAIN·c` (c the
/// clipped command × 0.05 m), the rotation vector likewise (× 0.5 rad); the controller re-anchors
/// its goal at the measured pose every step, so the arm covers about 29 % of a sustained position
/// command and 14 % of a rotation command per step.
const POS_KEEP: f64 = 0.7044;
const POS_GAIN: f64 = 0.0856;
const ROT_KEEP: f64 = 0.5032;
const ROT_GAIN: f64 = 0.0700;
/// The fingers' first-order pull towards their servo targets per step (least squares on the
/// same seeds' opening steps, where nothing stops them). Closing on an object is not modelled:
/// the estimate closes fully where a grasped cube or can holds the real fingers apart.
const FINGER_PULL: f64 = 0.3292;

/// The imagined branch's estimate of the state: what the episode showed at reset, moved by a
/// model of how the arm follows each command since.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobotEstimate {
    pos: [f64; 3],
    /// The last step's displacement.
    vel: [f64; 3],
    /// (w, x, y, z).
    quat: [f64; 4],
    /// The last step's rotation vector.
    turn: [f64; 3],
    fingers: [f64; 2],
    /// The gripper's running command (the controller's, from 0 at reset).
    grip: [f64; 2],
}

impl RobotEstimate {
    /// The state measured at reset.
    pub fn at_reset(ep: &ArmEpisode) -> Self {
        Self::from_state(ep.eef_pos(), ep.hand_quat(), ep.fingers())
    }

    /// At rest at these measurements.
    pub fn from_state(pos: [f64; 3], quat: [f64; 4], fingers: [f64; 2]) -> Self {
        Self { pos, vel: [0.0; 3], quat, turn: [0.0; 3], fingers, grip: [0.0; 2] }
    }

    /// Takes one executed action (entries clipped to [-1, 1], as the controller clips them).
    pub fn advance(&mut self, action: &[f32]) {
        let a = |d: usize| f64::from(action.get(d).copied().unwrap_or(0.0).clamp(-1.0, 1.0));
        for d in 0..3 {
            self.vel[d] = POS_KEEP * self.vel[d] + POS_GAIN * a(d) * MAX_DPOS;
            self.pos[d] += self.vel[d];
            self.turn[d] = ROT_KEEP * self.turn[d] + ROT_GAIN * a(3 + d) * MAX_DROT;
        }
        let step = mat_to_quat(&axis_angle_to_mat(self.turn));
        self.quat = normalise(quat_mul(step, self.quat));
        if action.len() > 6 {
            self.grip = grip_step(self.grip, a(6));
        }
        for i in 0..2 {
            self.fingers[i] += FINGER_PULL * (finger_target(i, self.grip[i]) - self.fingers[i]);
        }
    }

    /// The estimate laid out as [`keys`].
    pub fn vector(&self) -> Vec<f32> {
        let [w, x, y, z] = self.quat;
        let mut v: Vec<f32> = self.pos.iter().map(|&p| p as f32).collect();
        v.extend([x, y, z, w].map(|c| c as f32));
        v.extend(self.fingers.map(|f| f as f32));
        v
    }
}

/// Hamilton product a ⊗ b of (w, x, y, z) quaternions.
pub(crate) fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
}

/// The rotation vector (axis × angle, the angle in [0, π]) of a (w, x, y, z) quaternion (the
/// fit and measurement of the model read the arm's turns with it).
#[cfg(test)]
pub(crate) fn rotvec(q: [f64; 4]) -> [f64; 3] {
    let q = if q[0] < 0.0 { q.map(|c| -c) } else { q };
    let n = (q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    if n < 1e-12 {
        return [2.0 * q[1], 2.0 * q[2], 2.0 * q[3]];
    }
    let angle = 2.0 * n.atan2(q[0]);
    [q[1] / n * angle, q[2] / n * angle, q[3] / n * angle]
}

fn normalise(q: [f64; 4]) -> [f64; 4] {
    let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
    if n > 0.0 { q.map(|c| c / n) } else { [1.0, 0.0, 0.0, 0.0] }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &[f32], b: &[f32], tol: f32) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
    }

    #[test]
    fn a_held_command_moves_the_estimate_as_the_fitted_model_does() {
        let mut e = RobotEstimate::from_state([0.1, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0], [0.02, -0.02]);
        // Two steps of +1 in x: v1 = 0.0856 · 0.05 = 0.00428 m, v2 = 0.7044 · 0.00428 + 0.00428
        // = 0.0072949 m, so x = 0.1 + 0.0115749. A +1 yaw on the second step: a turn of
        // 0.0700 · 0.5 = 0.035 rad about z, the quaternion (cos 0.0175, 0, 0, sin 0.0175)
        // = (0.999847, 0, 0, 0.0174991), written x y z w.
        e.advance(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        e.advance(&[1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        let want = [0.111_574_9, 0.0, 1.0, 0.0, 0.0, 0.017_499_1, 0.999_847];
        assert!(close(&e.vector()[..7], &want, 1e-6), "{:?}", e.vector());
        // Out-of-range commands are clipped as the controller clips them: 3.0 acts as 1.0.
        let (mut a, mut b) = (e, e);
        a.advance(&[3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        b.advance(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(a, b);
    }

    #[test]
    fn the_fingers_follow_the_running_gripper_command() {
        let mut e = RobotEstimate::from_state([0.0; 3], [1.0, 0.0, 0.0, 0.0], [0.02, -0.02]);
        // One closing step: the running command moves to [−0.2, 0.2], the targets to
        // 0.02 + 0.02 · (−0.2) = 0.016 and −0.02 + 0.02 · 0.2 = −0.016, and each finger moves
        // FINGER_PULL of the way there.
        e.advance(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        let f = (0.02 + FINGER_PULL * (0.016 - 0.02)) as f32;
        assert!(close(&e.vector()[7..], &[f, -f], 1e-7), "{:?}", e.vector());
        // Held open long enough, the fingers reach the open stops, ±0.04.
        (0..200).for_each(|_| e.advance(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0]));
        assert!(close(&e.vector()[7..], &[0.04, -0.04], 1e-5), "{:?}", e.vector());
    }

    #[test]
    fn rotation_vectors_round_trip() {
        // A quarter turn about y: (cos π/4, 0, sin π/4, 0) → (0, π/2, 0).
        let h = std::f64::consts::FRAC_PI_4;
        let v = rotvec([h.cos(), 0.0, h.sin(), 0.0]);
        assert!((v[1] - 2.0 * h).abs() < 1e-12 && v[0].abs() < 1e-12 && v[2].abs() < 1e-12, "{v:?}");
        // The same rotation written with w < 0 gives the same vector.
        assert_eq!(rotvec([-h.cos(), 0.0, -h.sin(), 0.0]), v);
    }
}
