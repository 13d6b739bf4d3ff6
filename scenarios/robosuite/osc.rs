//! robosuite's default Panda controller: OSC_POSE for the arm and GRIP for the
//! Panda gripper, stepped as robosuite 1.5.2 steps them.
//!
//! One control step (20 Hz) is 25 physics steps of 0.002 s. Each physics step
//! runs `mj_step1`, then the controller on the state it computed, then `mj_step2`
//! (robosuite's `lite_physics`). The goal is set on the first physics step only:
//! - the action's first six entries, clipped to [−1, 1], scale to a position
//!   delta of ≤ 0.05 m and an axis-angle delta of ≤ 0.5 rad;
//! - goal position = grip-site position + delta; goal orientation =
//!   R(axis-angle delta) · grip-site orientation (the "achieved" update mode; the
//!   Panda's base is not rotated, so the base frame is the world's);
//! - the seventh entry moves the gripper's running command by ±0.2 towards
//!   closed (> 0) or open (< 0), clipped to [−1, 1].
//!
//! Every physics step then applies
//! `τ = Jᵀ [Λ_pos (kp e_pos − kd v), Λ_ori (kp e_ori − kd ω)] + bias + Nᵀ M (kp_null (q₀ − q) − kd_null q̇)`,
//! kp = 150, kd = 2 √kp (damping ratio 1), kp_null = 10, kd_null = 2 √10, with
//! `Λ = pinv(J M⁻¹ Jᵀ)` per block, `N = I − M⁻¹ Jᵀ Λ_full J`, and clips τ to the
//! actuators' ranges (±80 N m, ±12 N m on the wrist).

use std::sync::Arc;

use mujoco_rs::prelude::*;

use super::linalg::{Mat, identity, mul, mul_vec, spd_inverse, sym_pinv, transpose};
use super::scene::{ARM_JOINTS, FINGER_JOINTS, GRIP_SITE};
use crate::error::ScenarioError;

/// The simulation data the controller drives.
pub type Data = MjData<Arc<MjModel>>;

/// Physics steps per control step: 0.05 s / 0.002 s.
pub const SUBSTEPS: usize = 25;
/// The arm's stiffness, N/m and N m/rad.
const KP: f64 = 150.0;
/// Null-space posture stiffness.
const KP_NULL: f64 = 10.0;
/// Largest position delta per control step, m.
pub(super) const MAX_DPOS: f64 = 0.05;
/// Largest rotation delta per control step, rad.
pub(super) const MAX_DROT: f64 = 0.5;
/// How far one control step moves the gripper's running command.
const GRIPPER_SPEED: f64 = 0.2;

/// Where the Panda's quantities live in the compiled model.
#[derive(Clone, Debug)]
pub struct PandaIndex {
    /// qpos addresses of the arm joints.
    pub arm_qpos: [usize; 7],
    /// dof addresses of the arm joints.
    pub arm_dof: [usize; 7],
    /// qpos addresses of the finger joints.
    pub finger_qpos: [usize; 2],
    /// Actuator ids of the arm motors.
    pub arm_act: [usize; 7],
    /// Actuator ids of the finger position servos.
    pub finger_act: [usize; 2],
    /// Control ranges of the arm motors and finger servos.
    pub ctrlrange: [[f64; 2]; 9],
    /// The grip site.
    pub grip_site: usize,
}

impl PandaIndex {
    /// Looks the Panda up by robosuite's names.
    ///
    /// # Errors
    /// [`ScenarioError::Model`] naming the joint, actuator or site not found.
    pub fn new(m: &MjModel) -> Result<Self, ScenarioError> {
        let miss = |kind: &str, name: &str| ScenarioError::Model {
            scenario: "robosuite".into(),
            message: format!("the composed model has no {kind} '{name}'"),
        };
        let joint = |name: &str| m.joint(name).ok_or_else(|| miss("joint", name));
        let mut arm_qpos = [0; 7];
        let mut arm_dof = [0; 7];
        let mut arm_act = [0; 7];
        let mut ctrlrange = [[0.0; 2]; 9];
        let ranges = m.actuator_ctrlrange();
        for (i, name) in ARM_JOINTS.iter().enumerate() {
            let j = joint(name)?;
            arm_qpos[i] = m.jnt_qposadr()[j.id] as usize;
            arm_dof[i] = m.jnt_dofadr()[j.id] as usize;
            let act = format!("robot0_torq_j{}", i + 1);
            arm_act[i] = m.actuator(&act).ok_or_else(|| miss("actuator", &act))?.id;
            ctrlrange[i] = ranges[arm_act[i]];
        }
        let mut finger_qpos = [0; 2];
        let mut finger_act = [0; 2];
        for (i, name) in FINGER_JOINTS.iter().enumerate() {
            finger_qpos[i] = m.jnt_qposadr()[joint(name)?.id] as usize;
            let act = format!("gripper0_right_gripper_finger_joint{}", i + 1);
            finger_act[i] = m.actuator(&act).ok_or_else(|| miss("actuator", &act))?.id;
            ctrlrange[7 + i] = ranges[finger_act[i]];
        }
        let grip_site = m.site(GRIP_SITE).ok_or_else(|| miss("site", GRIP_SITE))?.id;
        Ok(Self { arm_qpos, arm_dof, finger_qpos, arm_act, finger_act, ctrlrange, grip_site })
    }
}

/// The rotation matrix of an axis-angle vector (Rodrigues; robosuite's
/// `quat2mat(axisangle2quat(v))`).
pub fn axis_angle_to_mat(v: [f64; 3]) -> Mat<3, 3> {
    let angle = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if angle == 0.0 {
        return identity();
    }
    let [x, y, z] = v.map(|c| c / angle);
    let (s, c) = angle.sin_cos();
    let t = 1.0 - c;
    [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]
}

/// robosuite's `orientation_error(desired, current)`: half the sum of the cross
/// products of matching columns.
pub fn orientation_error(desired: &Mat<3, 3>, current: &Mat<3, 3>) -> [f64; 3] {
    let mut e = [0.0; 3];
    for c in 0..3 {
        let (a, b) =
            ([current[0][c], current[1][c], current[2][c]], [desired[0][c], desired[1][c], desired[2][c]]);
        e[0] += 0.5 * (a[1] * b[2] - a[2] * b[1]);
        e[1] += 0.5 * (a[2] * b[0] - a[0] * b[2]);
        e[2] += 0.5 * (a[0] * b[1] - a[1] * b[0]);
    }
    e
}

/// The scripted behaviours' position gain: a 1 cm error asks for 0.2 of the
/// controller's 0.05 m step.
pub const SERVO_POS_GAIN: f64 = 10.0;
/// The scripted behaviours' rotation gain per radian, in units of the 0.5 rad step.
pub const SERVO_ROT_GAIN: f64 = 4.0;

/// A proportional action toward a pose: the position error `err` (m) and the
/// orientation error `rot` (rad, [`orientation_error`]) scaled by the servo
/// gains and clipped to [−1, 1], then the gripper command.
pub fn servo_action(err: [f64; 3], rot: [f64; 3], grip: f64) -> [f64; 7] {
    let mut a = [0.0; 7];
    for i in 0..3 {
        a[i] = (SERVO_POS_GAIN * err[i]).clamp(-1.0, 1.0);
        a[3 + i] = (SERVO_ROT_GAIN * rot[i]).clamp(-1.0, 1.0);
    }
    a[6] = grip;
    a
}

/// The gripper pointing straight down with its x axis at `yaw` about z. Columns:
/// x = (c, s, 0), y = z × x = (s, −c, 0), z = (0, 0, −1); a proper rotation.
pub fn pointing_down(yaw: f64) -> Mat<3, 3> {
    let (s, c) = yaw.sin_cos();
    [[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]]
}

/// The grip site's pose, the arm's Jacobians, mass matrix and bias forces, read
/// after `mj_step1`.
struct ArmState {
    pos: [f64; 3],
    ori: Mat<3, 3>,
    jp: Mat<3, 7>,
    jr: Mat<3, 7>,
    vel: [f64; 3],
    omega: [f64; 3],
    q: [f64; 7],
    qd: [f64; 7],
    mass: Mat<7, 7>,
    bias: [f64; 7],
}

fn read(d: &Data, ix: &PandaIndex, nv: usize) -> ArmState {
    let x = d.site_xmat()[ix.grip_site];
    let ori = [[x[0], x[1], x[2]], [x[3], x[4], x[5]], [x[6], x[7], x[8]]];
    let (jp_all, jr_all) = d.jac_site(true, true, ix.grip_site);
    let (qpos, qvel, bias_all) = (d.qpos(), d.qvel(), d.qfrc_bias());
    let mut jp = [[0.0; 7]; 3];
    let mut jr = [[0.0; 7]; 3];
    let (mut vel, mut omega) = ([0.0; 3], [0.0; 3]);
    for r in 0..3 {
        for (c, &dof) in ix.arm_dof.iter().enumerate() {
            jp[r][c] = jp_all[r * nv + dof];
            jr[r][c] = jr_all[r * nv + dof];
        }
        // Velocities use every dof, as robosuite's get_site_xvelp does.
        vel[r] = (0..nv).map(|k| jp_all[r * nv + k] * qvel[k]).sum();
        omega[r] = (0..nv).map(|k| jr_all[r * nv + k] * qvel[k]).sum();
    }
    let mut full = vec![0.0; nv * nv];
    d.full_m(&mut full).expect("buffer of nv * nv");
    let mut mass = [[0.0; 7]; 7];
    for (i, &a) in ix.arm_dof.iter().enumerate() {
        for (j, &b) in ix.arm_dof.iter().enumerate() {
            mass[i][j] = full[a * nv + b];
        }
    }
    ArmState {
        pos: d.site_xpos()[ix.grip_site],
        ori,
        jp,
        jr,
        vel,
        omega,
        q: ix.arm_qpos.map(|a| qpos[a]),
        qd: ix.arm_dof.map(|a| qvel[a]),
        mass,
        bias: ix.arm_dof.map(|a| bias_all[a]),
    }
}

/// The gripper's running command after a step of gripper command `g`: each finger's entry moves
/// [`GRIPPER_SPEED`] towards closing (`g` > 0) or opening (`g` < 0), in opposite directions,
/// within [−1, 1] (`np.sign`: 0 leaves it where it is).
pub(super) fn grip_step(grip: [f64; 2], g: f64) -> [f64; 2] {
    let sign = if g > 0.0 {
        1.0
    } else if g < 0.0 {
        -1.0
    } else {
        0.0
    };
    [(grip[0] - GRIPPER_SPEED * sign).clamp(-1.0, 1.0), (grip[1] + GRIPPER_SPEED * sign).clamp(-1.0, 1.0)]
}

/// A finger servo's target for the gripper's running command `c` in [−1, 1]: linear onto its
/// control range `[lo, hi]` (GRIP).
pub(super) fn servo_target([lo, hi]: [f64; 2], c: f64) -> f64 {
    0.5 * (lo + hi) + 0.5 * (hi - lo) * c
}

/// The controller's state across control steps.
#[derive(Clone, Debug)]
pub struct Osc {
    index: PandaIndex,
    goal_pos: [f64; 3],
    goal_ori: Mat<3, 3>,
    /// The posture the null space pulls toward: the joints at reset.
    initial_joint: [f64; 7],
    /// PandaGripper's running two-finger command in [−1, 1].
    gripper: [f64; 2],
}

impl Osc {
    /// A controller for the data's current state (call after the reset's
    /// `mj_forward`): the goal is the current grip-site pose, the null-space
    /// posture the current joints, the gripper command zero.
    pub fn new(d: &Data, index: PandaIndex) -> Self {
        let nv = d.qvel().len();
        let s = read(d, &index, nv);
        Self { goal_pos: s.pos, goal_ori: s.ori, initial_joint: s.q, gripper: [0.0; 2], index }
    }

    /// The indices the controller uses.
    pub fn index(&self) -> &PandaIndex {
        &self.index
    }

    #[allow(clippy::needless_range_loop)]
    fn set_goal(&mut self, s: &ArmState, action: &[f64; 7]) {
        let a = action.map(|v| v.clamp(-1.0, 1.0));
        for i in 0..3 {
            self.goal_pos[i] = s.pos[i] + a[i] * MAX_DPOS;
        }
        let rot = axis_angle_to_mat([a[3] * MAX_DROT, a[4] * MAX_DROT, a[5] * MAX_DROT]);
        self.goal_ori = mul(&rot, &s.ori);
        // np.sign: 0 leaves the command where it is. The raw (unclipped) entry decides.
        self.gripper = grip_step(self.gripper, action[6]);
    }

    #[allow(clippy::needless_range_loop)]
    fn torques(&self, s: &ArmState) -> [f64; 7] {
        let kd = 2.0 * KP.sqrt();
        let e_ori = orientation_error(&self.goal_ori, &s.ori);
        let mut force = [0.0; 3];
        let mut torque = [0.0; 3];
        for i in 0..3 {
            force[i] = KP * (self.goal_pos[i] - s.pos[i]) - kd * s.vel[i];
            torque[i] = KP * e_ori[i] - kd * s.omega[i];
        }
        let Some(minv) = spd_inverse(&s.mass) else {
            // A mass matrix that is not positive definite means the state is
            // broken; the divergence check stops the episode on the next step.
            return s.bias;
        };
        let mut jfull = [[0.0; 7]; 6];
        jfull[..3].copy_from_slice(&s.jp);
        jfull[3..].copy_from_slice(&s.jr);
        let lam_pos = sym_pinv(&mul(&mul(&s.jp, &minv), &transpose(&s.jp)));
        let lam_ori = sym_pinv(&mul(&mul(&s.jr, &minv), &transpose(&s.jr)));
        let lam_full = sym_pinv(&mul(&mul(&jfull, &minv), &transpose(&jfull)));
        let f = mul_vec(&lam_pos, &force);
        let t = mul_vec(&lam_ori, &torque);
        let wrench = [f[0], f[1], f[2], t[0], t[1], t[2]];
        let mut tau = mul_vec(&transpose(&jfull), &wrench);
        // Null space: N = I − J̄ J with J̄ = M⁻¹ Jᵀ Λ_full; torques Nᵀ M (kp Δq − kd q̇).
        let jbar = mul(&mul(&minv, &transpose(&jfull)), &lam_full);
        let jbar_j = mul(&jbar, &jfull);
        let mut n = identity::<7>();
        for i in 0..7 {
            for j in 0..7 {
                n[i][j] -= jbar_j[i][j];
            }
        }
        let kd_null = 2.0 * KP_NULL.sqrt();
        let mut pull = [0.0; 7];
        for i in 0..7 {
            pull[i] = KP_NULL * (self.initial_joint[i] - s.q[i]) - kd_null * s.qd[i];
        }
        let posture = mul_vec(&s.mass, &pull);
        let null = mul_vec(&transpose(&n), &posture);
        for i in 0..7 {
            tau[i] += s.bias[i] + null[i];
        }
        tau
    }

    /// One control step: 25 physics steps under `action` (7 entries, robomimic's
    /// layout: Δposition, Δaxis-angle, gripper).
    ///
    /// `shown` receives the joint positions of the last substep's kinematics: after
    /// the step, MuJoCo's body and geom poses (what a frame shows) are those, not the
    /// integrated `qpos`.
    pub fn step(&mut self, d: &mut Data, action: &[f64; 7], shown: &mut [f64]) {
        let nv = d.qvel().len();
        for sub in 0..SUBSTEPS {
            if sub + 1 == SUBSTEPS {
                shown.copy_from_slice(d.qpos());
            }
            d.step1();
            let s = read(d, &self.index, nv);
            if sub == 0 {
                self.set_goal(&s, action);
            }
            let tau = self.torques(&s);
            let ix = &self.index;
            let ctrl = d.ctrl_mut();
            for i in 0..7 {
                let [lo, hi] = ix.ctrlrange[i];
                ctrl[ix.arm_act[i]] = tau[i].clamp(lo, hi);
            }
            for i in 0..2 {
                // GRIP: the command in [−1, 1] maps linearly onto the servo's range.
                ctrl[ix.finger_act[i]] = servo_target(ix.ctrlrange[7 + i], self.gripper[i]);
            }
            d.step2();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotations_and_their_errors() {
        // A quarter turn about z maps x to y: the matrix's first column is (0, 1, 0).
        let r = axis_angle_to_mat([0.0, 0.0, std::f64::consts::FRAC_PI_2]);
        assert!((r[1][0] - 1.0).abs() < 1e-12 && r[0][0].abs() < 1e-12, "{r:?}");
        // The error from identity to a small rotation about z by 0.1 rad:
        // ½ Σ cᵢ × dᵢ = ½ (sin 0.1 + sin 0.1) ẑ = sin(0.1) ẑ ≈ 0.0998 ẑ.
        let d = axis_angle_to_mat([0.0, 0.0, 0.1]);
        let e = orientation_error(&d, &identity());
        assert!(e[0].abs() < 1e-12 && e[1].abs() < 1e-12, "{e:?}");
        assert!((e[2] - 0.1_f64.sin()).abs() < 1e-12, "{e:?}");
    }
}
