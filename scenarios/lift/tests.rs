//! Lift on tiny episodes: seeded resets, the controller tracking a commanded
//! pose, success detection and the expert.

use super::*;
use crate::robosuite::osc::{axis_angle_to_mat, orientation_error};
use crate::robosuite::rollout::{Perturbation, RunLimits};

fn sim() -> LiftSim {
    LiftSim::new(LiftConfig::default()).expect("robosuite assets (scripts/setup.sh)")
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

#[test]
fn the_reset_is_a_pure_function_of_the_seed() {
    let cfg = LiftConfig::default();
    assert_eq!(LiftInit::draw(&cfg, 7), LiftInit::draw(&cfg, 7));
    assert_ne!(LiftInit::draw(&cfg, 7), LiftInit::draw(&cfg, 8));
    let i = LiftInit::draw(&cfg, 7);
    // The cube rests its bottom 0.01 m over the 0.8 m table top: z = 0.81 + half height.
    assert!((i.cube_pos[2] - (0.81 + i.cube_half[2])).abs() < 1e-12);
    assert!(i.cube_pos[0].abs() <= 0.03 && i.cube_pos[1].abs() <= 0.03);
    assert!(i.cube_half.iter().all(|h| (0.020..=0.022).contains(h)));
    // Two resets of one seed step identically.
    let s = sim();
    let (mut a, mut b) = (s.reset(7).unwrap(), s.reset(7).unwrap());
    for _ in 0..3 {
        a.step(&[0.3, -0.2, 0.1, 0.0, 0.1, 0.0, 1.0]).unwrap();
        b.step(&[0.3, -0.2, 0.1, 0.0, 0.1, 0.0, 1.0]).unwrap();
    }
    assert_eq!(a.state(), b.state());
}

#[test]
fn the_controller_holds_still_and_tracks_a_commanded_pose() {
    let s = sim();
    let mut ep = s.reset(3).unwrap();
    let start = ep.arm().eef_pos();
    // A zero action asks to stay: gravity compensation and the held goal keep
    // the grip site within a millimetre over 20 steps (1 s).
    for _ in 0..20 {
        ep.step(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0]).unwrap();
    }
    let drift = norm([0, 1, 2].map(|i| ep.arm().eef_pos()[i] - start[i]));
    assert!(drift < 1e-3, "drifted {drift} m");
    // Track a pose 8 cm away, turned 0.3 rad about z, with a proportional action.
    let target = [start[0] + 0.05, start[1] - 0.04, start[2] - 0.06];
    let goal_ori = crate::robosuite::linalg::mul(&axis_angle_to_mat([0.0, 0.0, 0.3]), &ep.arm().eef_mat());
    for _ in 0..40 {
        let p = ep.arm().eef_pos();
        let r = orientation_error(&goal_ori, &ep.arm().eef_mat());
        let mut a = [0.0; 7];
        for i in 0..3 {
            a[i] = (10.0 * (target[i] - p[i])).clamp(-1.0, 1.0);
            a[3 + i] = (4.0 * r[i]).clamp(-1.0, 1.0);
        }
        a[6] = -1.0;
        ep.step(&a).unwrap();
    }
    let err = norm([0, 1, 2].map(|i| ep.arm().eef_pos()[i] - target[i]));
    let rot = norm(orientation_error(&goal_ori, &ep.arm().eef_mat()));
    assert!(err < 2e-3, "position error {err} m");
    assert!(rot < 0.01, "orientation error {rot} rad");
}

#[test]
fn success_is_the_cube_centre_above_table_plus_four_centimetres() {
    let s = sim();
    let base = LiftInit::draw(s.config(), 1);
    // Table top 0.8 m + 0.04 m: a centre at 0.841 m counts, 0.839 m does not.
    let at = |z: f64| {
        let mut i = base;
        i.cube_pos[2] = z;
        s.reset_to(1, i).unwrap()
    };
    assert!(at(0.841).success());
    assert!(!at(0.839).success());
    // Released from 0.841 m, the cube falls to the table: no longer a success.
    let mut ep = at(0.841);
    for _ in 0..10 {
        ep.step(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0]).unwrap();
    }
    assert!(!ep.success(), "cube at {:?}", ep.arm().object_pos());
}

#[test]
fn the_expert_lifts_and_a_miss_does_not() {
    let s = sim();
    let limits = RunLimits { max_steps: 80, stop_at_success: true, frame_size: None };
    for seed in 0..3 {
        let ep = s.episode(seed, LiftBehaviour::Expert, Perturbation::default(), limits).unwrap();
        assert!(ep.success, "seed {seed}: {} steps", ep.rows.len());
        assert!(ep.rows.last().unwrap().success, "ends at the first success");
        let miss = s.episode(seed, LiftBehaviour::Miss, Perturbation::default(), limits).unwrap();
        assert!(!miss.success, "seed {seed}");
        assert_eq!(miss.rows.len(), 80);
    }
}

#[test]
fn a_non_finite_action_names_the_seed_and_step() {
    let s = sim();
    let mut ep = s.reset(5).unwrap();
    ep.step(&[0.0; 7]).unwrap();
    let e = ep.step(&[f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]).unwrap_err().to_string();
    assert!(e.contains("seed 5") && e.contains("step 1"), "{e}");
}

#[test]
fn exploring_is_seeded_and_turns_the_wrist_further_than_the_expert() {
    let s = sim();
    let limits = RunLimits { max_steps: 60, stop_at_success: false, frame_size: None };
    let ep = |b| s.episode(4, b, Perturbation::default(), limits).unwrap();
    let (a, b, expert) = (ep(LiftBehaviour::Explore), ep(LiftBehaviour::Explore), ep(LiftBehaviour::Expert));
    let actions = |e: &LiftEpisodeRecord| e.rows.iter().map(|r| r.action).collect::<Vec<_>>();
    assert_eq!(actions(&a), actions(&b), "a pure function of the seed");
    // The summed rotation commands (entries 3-5) over the episode: the drift's
    // lapses and offsets turn the wrist more than the expert's servo does.
    let turn = |e: &LiftEpisodeRecord| {
        e.rows.iter().map(|r| r.action[3..6].iter().map(|v| v.abs()).sum::<f64>()).sum::<f64>()
    };
    assert!(turn(&a) > 2.0 * turn(&expert), "explore {} against expert {}", turn(&a), turn(&expert));
    assert_eq!(LiftBehaviour::parse("explore"), Some(LiftBehaviour::Explore));
}
