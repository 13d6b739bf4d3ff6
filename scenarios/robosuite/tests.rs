//! Tests of the composed robosuite scenes against numbers read off robosuite's
//! own model (`robosuite.make("Lift", robots="Panda", seed=0)`, 1.5.2 on
//! MuJoCo 3.17.0, printed by `scripts/crosscheck_robosuite.py --dump`).

use std::sync::Arc;

use mujoco_rs::prelude::*;

use super::assets::assets_dir;
use super::scene::{SceneBuilder, Table};
use crate::lift::LiftConfig;
use crate::lift::sim::{LiftInit, LiftSim, lift_model};

fn lift_scene() -> MjModel {
    let dir = assets_dir().expect("robosuite assets (scripts/setup.sh)");
    let mut b =
        SceneBuilder::table_arena(&dir, &Table::LIFT, &crate::robosuite::visual::Visual::cheap()).unwrap();
    // Lift: base at (-0.16 - 0.8 / 2, 0, 0) raised by the mount's 0.912 m.
    b.panda([-0.56, 0.0, 0.912]).unwrap();
    b.compile("lift").unwrap()
}

#[test]
fn the_lift_scene_has_robosuites_bodies_masses_and_joint_settings() {
    let m = lift_scene();
    assert_eq!((m.ffi().nq, m.ffi().nu), (9, 9), "7 arm joints + 2 fingers, 9 actuators");
    let body = |name: &str| m.body(name).unwrap_or_else(|| panic!("no body {name}")).id;
    // Positions relative to the parent, as robosuite's compiled model has them.
    assert_eq!(m.body_pos()[body("table")], [0.0, 0.0, 0.775], "0.8 top − 0.025 half thickness");
    assert_eq!(m.body_pos()[body("robot0_base")], [-0.56, 0.0, 0.912]);
    assert_eq!(m.body_pos()[body("fixed_mount0_base")], [0.0, 0.0, 0.01]);
    assert_eq!(m.body_pos()[body("gripper0_right_eef")], [0.0, 0.0, 0.097]);
    // The table's mass comes from its collision box only (inertiagrouprange 0 0):
    // 1000 kg/m³ × 0.8 × 0.8 × 0.05 m³ = 32 kg.
    assert!((m.body_mass()[body("table")] - 32.0).abs() < 1e-9);
    let links: Vec<f64> = (0..8).map(|i| m.body_mass()[body(&format!("robot0_link{i}"))]).collect();
    assert_eq!(links, [4.0, 3.0, 3.0, 2.0, 2.0, 2.0, 1.5, 0.5]);
    assert_eq!(m.body_mass()[body("fixed_mount0_pedestal_feet")], 167.09);
    // robosuite's joint defaults: armature 5 / (i + 1), damping 0.1 ×5 and 0.01 ×2,
    // frictionloss 0.1; the fingers keep the gripper file's 1, 100 and 1.
    let arm: Vec<f64> = m.dof_armature()[..7].to_vec();
    for (i, a) in arm.iter().enumerate() {
        assert!((a - 5.0 / (i as f64 + 1.0)).abs() < 1e-12, "{arm:?}");
    }
    assert_eq!(m.dof_damping()[..9], [0.1, 0.1, 0.1, 0.1, 0.1, 0.01, 0.01, 100.0, 100.0]);
    assert_eq!(m.dof_frictionloss()[..9], [0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1, 1.0, 1.0]);
    assert_eq!(m.opt().timestep, 0.002);
}

/// robosuite's seed-0 reset of the arm's joints (`robosuite.make("Lift", robots="Panda", seed=0)`).
const SEED0_ARM: [f64; 7] = [
    -0.010885179657146199,
    0.19002353772197897,
    0.008232610727482657,
    -2.5971436106026404,
    -0.0025706932588806853,
    2.968921923000787,
    0.772094269927716,
];

#[test]
fn the_grip_site_is_where_robosuite_puts_it_for_the_same_joints() {
    let m = Arc::new(lift_scene());
    let mut d = MjData::new(m.clone());
    // robosuite's seed-0 reset: the noisy initial joints and the fingers.
    d.qpos_mut()[..7].copy_from_slice(&SEED0_ARM);
    d.qpos_mut()[7..9].copy_from_slice(&[0.020833, -0.020833]);
    d.forward();
    let site = m.site("gripper0_right_grip_site").unwrap().id;
    let want = [-0.0853232205760393, -0.0008528129235318627, 1.0239900041318835];
    for (a, b) in d.site_xpos()[site].iter().zip(want) {
        assert!((a - b).abs() < 1e-12, "{:?} vs {want:?}", d.site_xpos()[site]);
    }
}

#[test]
fn the_cube_weighs_what_robosuites_does_for_the_same_size() {
    let dir = assets_dir().unwrap();
    // robosuite's seed-0 cube: half-sizes below, mass 0.07011070102818318 kg
    // (= 1000 × 8 × 0.020067 × 0.021459 × 0.020351).
    let half = [0.02006717115061093, 0.02145931089285989, 0.02035131124120512];
    let m = lift_model(&LiftConfig::default(), &dir, half).unwrap();
    let cube = m.body("cube_main").unwrap().id;
    assert!((m.body_mass()[cube] - 0.07011070102818318).abs() < 1e-15);
    let sim = LiftSim::new(LiftConfig::default()).unwrap();
    let init = LiftInit::draw(sim.config(), 0);
    let ep = sim.reset_to(0, init).unwrap();
    assert_eq!(ep.arm().arm_q(), init.arm_q);
}

/// What each rendering setting costs and changes (run by hand, `--ignored --nocapture`;
/// the criterion bench times the same settings).
#[test]
#[ignore = "a measurement, printed: cargo test -p scenarios frame_cost -- --ignored --nocapture"]
fn frame_cost_per_visual_setting() {
    use crate::robosuite::visual::Visual;
    let base = Visual::robosuite();
    let variants = [
        ("robosuite", base),
        ("offscreen 640x480", Visual { offscreen: [640, 480], ..base }),
        ("samples 0", Visual { samples: 0, ..base }),
        ("samples 1", Visual { samples: 1, ..base }),
        ("samples 2", Visual { samples: 2, ..base }),
        ("shadow 256", Visual { shadow_size: 256, ..base }),
        ("no reflections", Visual { reflections: false, ..base }),
        (
            "all cheap",
            Visual {
                offscreen: [96, 96],
                samples: 0,
                shadow_size: 256,
                reflections: false,
                render_size: None,
            },
        ),
        (
            "cheap, samples 4",
            Visual {
                offscreen: [96, 96],
                samples: 4,
                shadow_size: 256,
                reflections: false,
                render_size: None,
            },
        ),
    ];
    for task in ["lift", "can"] {
        let mut reference: Vec<Vec<u8>> = Vec::new();
        for (name, v) in variants {
            let action = |k: usize| {
                let s = if k % 20 < 10 { 0.3 } else { -0.3 };
                [s, -s, 0.0, 0.0, 0.0, 0.1 * s, 1.0]
            };
            let (frames, took) = frames_along(task, v, 3, 30, action);
            let per = took.as_secs_f64() * 1e3 / 30.0;
            if reference.is_empty() {
                reference = frames.clone();
            }
            let (mut sum, mut count, mut over8) = (0u64, 0u64, 0u64);
            for (a, b) in reference.iter().zip(&frames) {
                for (x, y) in a.iter().zip(b) {
                    let d = u64::from(x.abs_diff(*y));
                    sum += d;
                    count += 1;
                    over8 += u64::from(d > 8);
                }
            }
            eprintln!(
                "{task} {name:>18}: {per:6.1} ms per step+frame; mean |diff| {:.3}, {:.3}% of values > 8 levels",
                sum as f64 / count as f64,
                100.0 * over8 as f64 / count as f64
            );
        }
    }
}

#[test]
#[ignore = "a measurement, printed"]
fn model_sizes() {
    let lift = crate::lift::LiftSim::new(crate::lift::LiftConfig::default()).unwrap();
    let ep = lift.reset(1).unwrap();
    let _ = ep;
    let m = crate::lift::sim::lift_model(
        &crate::lift::LiftConfig::default(),
        &crate::robosuite::assets::assets_dir().unwrap(),
        [0.02; 3],
    )
    .unwrap();
    eprintln!("lift model {} bytes", m.size());
}

#[test]
fn frames_rendered_at_84_are_upsampled_as_driftworlds_robomimic_data() {
    // `[visual] render_size = 84`: the camera renders 84² and the frame is upsampled to 96²
    // with PyTorch's bilinear interpolation, as DriftWorld's robomimic loader did to
    // robomimic's 84² frames. The same state rendered at 84 by a default scene and upsampled
    // gives the same bytes; a direct 96² render differs.
    use crate::robosuite::visual::Visual;
    let at84 = Visual { render_size: Some(84), ..Visual::cheap() };
    let sim =
        crate::lift::LiftSim::new(crate::lift::LiftConfig { visual: at84, ..Default::default() }).unwrap();
    let plain = crate::lift::LiftSim::new(crate::lift::LiftConfig::default()).unwrap();
    let (mut a, mut b) = (sim.reset(5).unwrap(), plain.reset(5).unwrap());
    let frame = a.render(96).unwrap();
    let small = b.render(84).unwrap();
    let want = harness::resize::resize_bilinear_torch_u8(&small, 84, 84, 3, 96, 96).unwrap();
    assert_eq!(frame, want);
    let direct = b.render(96).unwrap();
    let mean =
        frame.iter().zip(&direct).map(|(x, y)| f64::from(x.abs_diff(*y))).sum::<f64>() / frame.len() as f64;
    assert!(mean > 0.1, "upsampled and direct renders should differ ({mean})");
    // What a policy observes: the upsampled frame and, beside it, the camera's own 84² frame
    // (a policy trained at 84 reads it instead of resizing the frame back); a scene rendering at
    // the observation's size gives none.
    use harness::task::Task;
    let task = crate::robosuite::task::RobosuiteTask::new(sim);
    let seen = task.reset(5).unwrap().observe();
    assert_eq!(seen.frame, want);
    let native = seen.native.expect("the camera's own frame");
    assert_eq!((native.side, native.bytes == small), (84, true));
    let plain = crate::robosuite::task::RobosuiteTask::new(plain);
    assert_eq!(plain.reset(5).unwrap().observe().native, None);
}

#[test]
fn the_shipped_robosuite_scenario_files_render_as_robosuite_and_differ_from_lifts_default() {
    // scenarios/{lift,can}_robosuite.toml: the task's defaults but for robosuite's rendering,
    // which is neither task's default (Lift's drops multisampling and reflections, Can's only
    // reflections).
    use crate::robosuite::visual::Visual;
    assert_eq!(crate::lift::LiftConfig::default().visual, Visual::cheap());
    assert_eq!(crate::can::CanConfig::default().visual, Visual::no_reflections());
    assert_eq!(Visual::no_reflections(), Visual { reflections: false, ..Visual::robosuite() });
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let lift = crate::lift::LiftConfig::from_file(&dir.join("lift_robosuite.toml")).unwrap();
    assert_eq!(lift, crate::lift::LiftConfig { visual: Visual::robosuite(), ..Default::default() });
    let can = crate::can::CanConfig::from_file(&dir.join("can_robosuite.toml")).unwrap();
    assert_eq!(can, crate::can::CanConfig { visual: Visual::robosuite(), ..Default::default() });
    // A file naming one setting keeps its task's default for the others.
    let tmp = tempfile::tempdir().unwrap();
    for (name, base) in [("lift", Visual::cheap()), ("can", Visual::no_reflections())] {
        let file = tmp.path().join(format!("{name}.toml"));
        std::fs::write(&file, format!("name = \"{name}\"\n[visual]\nrender_size = 84\n")).unwrap();
        let want = Visual { render_size: Some(84), ..base };
        let got = if name == "lift" {
            crate::lift::LiftConfig::from_file(&file).unwrap().visual
        } else {
            crate::can::CanConfig::from_file(&file).unwrap().visual
        };
        assert_eq!(got, want, "{name}");
    }
    // The two renderings draw other bytes of the same state (multisampled edges, the floor's
    // mirror image).
    let action = |_k: usize| [0.0; 7];
    let (ours, theirs) = (
        frames_along("lift", Visual::cheap(), 4, 1, action).0,
        frames_along("lift", Visual::robosuite(), 4, 1, action).0,
    );
    assert_ne!(ours, theirs);
    let (cans, robosuites) = (
        frames_along("can", Visual::no_reflections(), 4, 1, action).0,
        frames_along("can", Visual::robosuite(), 4, 1, action).0,
    );
    assert_ne!(cans, robosuites, "Can's floor without its mirror image");
}

#[test]
fn the_default_offscreen_buffer_renders_the_bytes_of_robosuites() {
    // The default buffer is the frame's size; robosuite's 640 x 480 one, which robomimic's
    // frames (and the shipped models' first training data) were rendered in, gives the same
    // bytes along a moving episode of each task (the arm sweeping, the gripper opening and
    // closing), with robosuite's multisampling and reflections.
    use crate::robosuite::visual::Visual;
    let ours = Visual::robosuite();
    let robosuites = Visual { offscreen: [640, 480], ..ours };
    assert_eq!((ours.offscreen, Visual::cheap().offscreen), ([96, 96], [96, 96]));
    let action = |k: usize| {
        let s = if k % 10 < 5 { 0.5 } else { -0.5 };
        [s, -s, -0.3, 0.0, 0.0, 0.2 * s, if k % 12 < 6 { 1.0 } else { -1.0 }]
    };
    for task in ["lift", "can"] {
        let (ours, theirs) =
            (frames_along(task, ours, 4, 12, action).0, frames_along(task, robosuites, 4, 12, action).0);
        assert!(ours.windows(2).any(|w| w[0] != w[1]), "{task}: the episode should move");
        assert!(ours == theirs, "{task}: a 96 x 96 buffer renders other bytes than robosuite's 640 x 480");
    }
}

/// The agentview frames of `steps` control steps of `task` (`lift` or `can`) from the reset of
/// `seed` rendered with `visual`, each after `action(step)`, and how long the steps and frames
/// took (not the reset); the thread's renderer is released after.
fn frames_along(
    task: &str,
    visual: crate::robosuite::visual::Visual,
    seed: u64,
    steps: usize,
    action: impl Fn(usize) -> [f64; 7],
) -> (Vec<Vec<u8>>, std::time::Duration) {
    let (mut lift, mut can);
    let arm = if task == "lift" {
        let sim =
            crate::lift::LiftSim::new(crate::lift::LiftConfig { visual, ..Default::default() }).unwrap();
        lift = sim.reset(seed).unwrap();
        lift.arm_mut()
    } else {
        let sim = crate::can::CanSim::new(crate::can::CanConfig { visual, ..Default::default() }).unwrap();
        can = sim.reset(seed).unwrap();
        can.arm_mut()
    };
    let t = std::time::Instant::now();
    let mut frames = Vec::with_capacity(steps);
    for k in 0..steps {
        arm.step(&action(k)).unwrap();
        frames.push(arm.render(96).unwrap());
    }
    let took = t.elapsed();
    crate::robosuite::renderer::release_renderer();
    (frames, took)
}

#[test]
fn the_robot_state_is_what_robosuite_reports_for_the_same_joints() {
    // robosuite 1.5.2's `robot0_eef_pos`, `robot0_eef_quat` (x y z w) and
    // `robot0_gripper_qpos` after setting these joints and `sim.forward()` (printed by a
    // throw-away script beside `scripts/crosscheck_robosuite.py`, with its MuJoCo 3.17 shims):
    // the seed-0 joints, then a turned wrist. Fingers at robosuite's initial opening.
    let cases: [([f64; 7], [f32; 9]); 2] = [
        (
            SEED0_ARM,
            [
                -0.085_323_22,
                -0.000_852_813,
                1.023_99,
                0.995_850_86,
                0.006_645_548,
                0.090_756_86,
                0.000_313_728,
                0.020_833,
                -0.020_833,
            ],
        ),
        (
            [0.3, 0.1, -0.2, -2.2, 0.4, 2.5, 1.9],
            [
                0.019_600_116,
                0.077_480_28,
                1.178_688_4,
                0.783_207_1,
                -0.600_828_5,
                0.011_152_009,
                -0.159_585_26,
                0.020_833,
                -0.020_833,
            ],
        ),
    ];
    for (q, want) in cases {
        let names = super::episode::ObjectNames { body: "cube_main", joint: "cube_joint0" };
        let pose = [0.0, 0.0, 0.83, 1.0, 0.0, 0.0, 0.0];
        let model = lift_model(&LiftConfig::default(), &assets_dir().unwrap(), [0.02; 3]).unwrap();
        let ep = super::episode::ArmEpisode::start("lift", 0, model, &names, q, pose).unwrap();
        let got = super::robot_state::measured(&ep);
        for (i, (a, b)) in got.iter().zip(want).enumerate() {
            assert!((a - b).abs() < 1e-6, "entry {i}: {got:?} vs {want:?}");
        }
        // At reset the imagined branch's estimate is the measurement.
        assert_eq!(super::robot_state::RobotEstimate::at_reset(&ep).vector(), got);
    }
}

/// The measured robot state: the grip site's position, the hand's orientation (w x y z), the fingers.
type Measured = ([f64; 3], [f64; 4], [f64; 2]);

/// Per control step along the expert's Lift episodes of `seeds` (120 steps each): the clipped
/// commands (scaled position and rotation deltas, gripper), and the measured robot state before
/// and after (the grip site's position, the hand's orientation w x y z, the fingers).
fn expert_steps(seeds: std::ops::Range<u64>) -> Vec<([f64; 7], Measured, Measured)> {
    let sim = crate::lift::LiftSim::new(LiftConfig::default()).unwrap();
    let mut out = Vec::new();
    for seed in seeds {
        let mut ep = sim.reset(seed).unwrap();
        let mut expert = crate::lift::expert::LiftExpert::new(Default::default());
        for _ in 0..120 {
            let a = expert.act(ep.arm());
            let state = |ep: &crate::lift::sim::LiftEpisode| {
                (ep.arm().eef_pos(), ep.arm().hand_quat(), ep.arm().fingers())
            };
            let before = state(&ep);
            ep.arm_mut().step(&a).unwrap();
            out.push((a, before, state(&ep)));
        }
    }
    out
}

#[test]
#[ignore = "a measurement (robosuite/robot_state.rs): cargo test -p scenarios robot_state_fit -- --ignored --nocapture"]
fn robot_state_fit_of_the_estimates_coefficients() {
    // Least squares on the expert's Lift seeds 0–4: per-step displacement v' = a·v + b·c (c the
    // clipped command × 0.05 m, axes pooled), per-step rotation vector likewise (× 0.5 rad), and
    // the fingers' first-order pull towards the gripper command's target.
    use super::robot_state::{quat_mul, rotvec};
    let steps = expert_steps(0..5);
    let solve = |rows: &[(f64, f64, f64)]| {
        let (mut s11, mut s12, mut s22, mut y1, mut y2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &(v, c, y) in rows {
            (s11, s12, s22, y1, y2) = (s11 + v * v, s12 + v * c, s22 + c * c, y1 + v * y, y2 + c * y);
        }
        let det = s11 * s22 - s12 * s12;
        ((y1 * s22 - y2 * s12) / det, (s11 * y2 - s12 * y1) / det)
    };
    let (mut pos_rows, mut rot_rows) = (Vec::new(), Vec::new());
    let (mut prev_v, mut prev_w) = ([0.0; 3], [0.0; 3]);
    for (k, (a, before, after)) in steps.iter().enumerate() {
        if k % 120 == 0 {
            (prev_v, prev_w) = ([0.0; 3], [0.0; 3]);
        }
        let v: [f64; 3] = std::array::from_fn(|i| after.0[i] - before.0[i]);
        let conj = [before.1[0], -before.1[1], -before.1[2], -before.1[3]];
        let w = rotvec(quat_mul(after.1, conj));
        for i in 0..3 {
            pos_rows.push((prev_v[i], a[i].clamp(-1.0, 1.0) * 0.05, v[i]));
            rot_rows.push((prev_w[i], a[3 + i].clamp(-1.0, 1.0) * 0.5, w[i]));
        }
        (prev_v, prev_w) = (v, w);
    }
    // Fingers: the running command moves 0.2 a step towards the gripper command's sign; each
    // finger's servo target is its range's middle plus the command times its half range.
    let (mut num, mut den, mut grip) = (0.0, 0.0, [0.0f64; 2]);
    for (k, (a, before, after)) in steps.iter().enumerate() {
        if k % 120 == 0 {
            grip = [0.0; 2];
        }
        grip = super::osc::grip_step(grip, a[6]);
        // Opening steps only: nothing stops the fingers there.
        for i in (0..2).filter(|_| a[6] < 0.0) {
            let target = super::robot_state::finger_target(i, grip[i]);
            num += (after.2[i] - before.2[i]) * (target - before.2[i]);
            den += (target - before.2[i]).powi(2);
        }
    }
    println!("fingers while opening, one-step least squares: q' = q + {:.4} (target - q)", num / den);
    // The pull whose estimate, run from reset, is nearest the measured fingers on average.
    let err_of = |k: f64| {
        let (mut err, mut q, mut grip) = (0.0, [0.0f64; 2], [0.0f64; 2]);
        for (j, (a, before, after)) in steps.iter().enumerate() {
            if j % 120 == 0 {
                (q, grip) = (before.2, [0.0; 2]);
            }
            grip = super::osc::grip_step(grip, a[6]);
            for i in 0..2 {
                q[i] += k * (super::robot_state::finger_target(i, grip[i]) - q[i]);
                err += (q[i] - after.2[i]).abs();
            }
        }
        err / (2 * steps.len()) as f64
    };
    let best =
        (1..=100).map(|i| f64::from(i) / 100.0).min_by(|a, b| err_of(*a).total_cmp(&err_of(*b))).unwrap();
    println!("fingers, run from reset: pull {best:.2}, mean error {:.2} mm", err_of(best) * 1000.0);
    println!("position: v' = {:.4} v + {:.4} c", solve(&pos_rows).0, solve(&pos_rows).1);
    println!("rotation: w' = {:.4} w + {:.4} r", solve(&rot_rows).0, solve(&rot_rows).1);
}

#[test]
#[ignore = "a measurement (docs/cli/import-policy.md): cargo test -p scenarios robot_state_estimate -- --ignored --nocapture"]
fn robot_state_estimate_along_expert_lift_episodes() {
    // How far the imagined branch's estimate drifts from the measured state along the scripted
    // expert's Lift episodes of seeds 5–9 (120 steps: approach, grasp, lift), which the
    // estimate's coefficients were not fitted on (seeds 0–4).
    use super::robot_state::{RobotEstimate, quat_mul, rotvec};
    let steps = expert_steps(5..10);
    let (mut pos, mut ang, mut fin) = (Vec::new(), Vec::new(), Vec::new());
    let mut est = RobotEstimate::from_state([0.0; 3], [1.0, 0.0, 0.0, 0.0], [0.0; 2]);
    for (k, (a, before, after)) in steps.iter().enumerate() {
        if k % 120 == 0 {
            est = RobotEstimate::from_state(before.0, before.1, before.2);
        }
        est.advance(&a.map(|v| v as f32));
        let e: Vec<f64> = est.vector().into_iter().map(f64::from).collect();
        pos.push((0..3).map(|i| (after.0[i] - e[i]).powi(2)).sum::<f64>().sqrt() * 1000.0);
        let q = [e[6], e[3], e[4], e[5]];
        let diff = quat_mul(after.1, [q[0], -q[1], -q[2], -q[3]]);
        ang.push(rotvec(diff).iter().map(|c| c * c).sum::<f64>().sqrt().to_degrees());
        fin.push((0..2).map(|i| (after.2[i] - e[7 + i]).abs()).fold(0.0, f64::max) * 1000.0);
    }
    let stats = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        (v.iter().sum::<f64>() / v.len() as f64, v[v.len() / 2], v[v.len() * 95 / 100], v[v.len() - 1])
    };
    println!("{} steps; mean, median, 95th percentile, max", steps.len());
    println!("eef position error, mm: {:.1?}", stats(&mut pos));
    println!("eef orientation error, degrees: {:.1?}", stats(&mut ang));
    println!("finger joint error, mm: {:.1?}", stats(&mut fin));
}
