//! The robot state robomimic policies read (robosuite 1.5's proprioceptive observables), measured
//! in the simulator and dead-reckoned from the commands in imagination.
//!
//! robosuite names them `robot0_eef_pos` (the grip site's position, m), `robot0_eef_quat` (the
//! `robot0_right_hand` body's orientation, x y z w: robosuite ≤ 1.5 reads the body, not the
//! site, so the two disagree by the gripper's mounting rotation) and `robot0_gripper_qpos` (the
//! two finger joints, m). A world model imagines frames only, so the imagined branch estimates
//! them from what the episode showed at reset and the commands since ([`RobotEstimate`]): the
//! position moves by each commanded delta (0.05 m per unit), the orientation turns by each
//! commanded rotation (0.5 rad per unit, world frame, as OSC_POSE composes its goal), and the
//! fingers sit where the last gripper command sends them (open ±0.04 m, closed 0). The
//! controller lags its goals and a grasped object stops the fingers, so the estimate is not the
//! measurement; a policy that leans on it can disagree between the branches for that reason.

use harness::task::StateKey;

use super::episode::ArmEpisode;
use super::osc::axis_angle_to_mat;

/// The keys, in the order of [`measured`] and [`RobotEstimate::vector`].
pub fn keys() -> Vec<StateKey> {
    vec![
        StateKey::new("robot0_eef_pos", 3),
        StateKey::new("robot0_eef_quat", 4),
        StateKey::new("robot0_gripper_qpos", 2),
    ]
}

/// Metres per unit of a position delta, radians per unit of a rotation delta (OSC_POSE).
const POS_SCALE: f64 = 0.05;
const ROT_SCALE: f64 = 0.5;
/// A finger joint's opening when the gripper is fully open, m.
const FINGER_OPEN: f64 = 0.04;

/// The measured state of an episode, as robosuite reports it.
pub fn measured(ep: &ArmEpisode) -> Vec<f32> {
    let [w, x, y, z] = ep.hand_quat();
    let mut v: Vec<f32> = ep.eef_pos().iter().map(|&p| p as f32).collect();
    v.extend([x, y, z, w].map(|c| c as f32));
    v.extend(ep.fingers().map(|f| f as f32));
    v
}

/// The imagined branch's estimate of the state: what the episode showed at reset, moved by
/// each command since.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobotEstimate {
    pos: [f64; 3],
    /// (w, x, y, z).
    quat: [f64; 4],
    fingers: [f64; 2],
}

impl RobotEstimate {
    /// The state measured at reset.
    pub fn at_reset(ep: &ArmEpisode) -> Self {
        Self { pos: ep.eef_pos(), quat: ep.hand_quat(), fingers: ep.fingers() }
    }

    /// Takes one executed action (entries clipped to [-1, 1], as the controller clips them).
    pub fn advance(&mut self, action: &[f32]) {
        let a = |d: usize| f64::from(action.get(d).copied().unwrap_or(0.0).clamp(-1.0, 1.0));
        for d in 0..3 {
            self.pos[d] += a(d) * POS_SCALE;
        }
        let turn = mat_quat(&axis_angle_to_mat([a(3), a(4), a(5)].map(|r| r * ROT_SCALE)));
        self.quat = normalise(quat_mul(turn, self.quat));
        if action.len() > 6 {
            // −1 open, +1 closed; the right finger's joint is the mirror of the left's.
            let open = FINGER_OPEN * (1.0 - a(6)) / 2.0;
            self.fingers = [open, -open];
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
fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    let [aw, ax, ay, az] = a;
    let [bw, bx, by, bz] = b;
    [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
}

fn normalise(q: [f64; 4]) -> [f64; 4] {
    let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
    if n > 0.0 { q.map(|c| c / n) } else { [1.0, 0.0, 0.0, 0.0] }
}

/// The rotation's quaternion with w ≥ 0 (a turn of under π has one).
fn mat_quat(m: &[[f64; 3]; 3]) -> [f64; 4] {
    super::episode::mat_to_quat(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &[f32], b: &[f32], tol: f32) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
    }

    #[test]
    fn the_estimate_follows_the_commanded_deltas() {
        let mut e =
            RobotEstimate { pos: [0.1, 0.0, 1.0], quat: [1.0, 0.0, 0.0, 0.0], fingers: [0.02, -0.02] };
        // Two steps of +1 in x: 2 · 0.05 m. A +1 yaw command: 0.5 rad about z, so the
        // quaternion is (cos 0.25, 0, 0, sin 0.25) = (0.968912, 0, 0, 0.247404), written x y z w.
        e.advance(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0]);
        e.advance(&[1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0]);
        let want = [0.2, 0.0, 1.0, 0.0, 0.0, 0.247_404, 0.968_912, 0.0, 0.0];
        assert!(close(&e.vector(), &want, 1e-6), "{:?}", e.vector());
        // An open command (−1) opens the fingers fully; a half command half-way.
        e.advance(&[0.0; 6].iter().copied().chain([-1.0]).collect::<Vec<_>>());
        assert!(close(&e.vector()[7..], &[0.04, -0.04], 1e-7));
        e.advance(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert!(close(&e.vector()[7..], &[0.02, -0.02], 1e-7));
        // Out-of-range commands are clipped as the controller clips them.
        let before = e.vector();
        e.advance(&[3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert!((e.vector()[0] - before[0] - 0.05).abs() < 1e-6);
    }

    #[test]
    fn two_half_turns_compose_to_one_turn() {
        let mut e = RobotEstimate { pos: [0.0; 3], quat: [1.0, 0.0, 0.0, 0.0], fingers: [0.0; 2] };
        // Two +1 roll commands: 1 rad about x; (x, y, z, w) = (sin 0.5, 0, 0, cos 0.5).
        e.advance(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
        e.advance(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0]);
        let want = [0.5f64.sin() as f32, 0.0, 0.0, 0.5f64.cos() as f32];
        assert!(close(&e.vector()[3..7], &want, 1e-6), "{:?}", e.vector());
    }
}
