//! Can on tiny episodes: seeded resets, success detection and the expert.

use super::*;
use crate::robosuite::rollout::{Perturbation, RunLimits};

fn sim() -> CanSim {
    CanSim::new(CanConfig::default()).expect("robosuite assets (scripts/setup.sh)")
}

#[test]
fn the_reset_is_a_pure_function_of_the_seed_inside_bin_one() {
    let cfg = CanConfig::default();
    assert_eq!(CanInit::draw(&cfg, 7), CanInit::draw(&cfg, 7));
    assert_ne!(CanInit::draw(&cfg, 7), CanInit::draw(&cfg, 8));
    for seed in 0..50 {
        let i = CanInit::draw(&cfg, seed);
        // Bin 1 spans 0.1 ± 0.195 by −0.25 ± 0.245; the can stays 0.05 m plus its
        // radius 0.0354 m inside: |dx| ≤ 0.1096, |dy| ≤ 0.1596.
        assert!((i.can_pos[0] - 0.1).abs() <= 0.1096 && (i.can_pos[1] + 0.25).abs() <= 0.1596, "{i:?}");
        // Standing on the bin: origin 0.06 m over 0.8 m.
        assert!((i.can_pos[2] - 0.86).abs() < 1e-12);
    }
}

#[test]
fn success_needs_the_target_quadrant_and_the_gripper_away() {
    let s = sim();
    let base = CanInit::draw(s.config(), 1);
    let at = |p: [f64; 3]| {
        let mut i = base;
        i.can_pos = p;
        s.reset_to(1, i).unwrap()
    };
    // The quadrant's centre (0.1975, 0.4025) at 0.86 m, the gripper ~0.6 m away.
    let inside = at([0.1975, 0.4025, 0.86]);
    assert!(inside.in_target_bin() && inside.success());
    // The neighbouring quadrant, or above the bin's 0.1 m band, does not count.
    assert!(!at([0.1975, 0.16, 0.86]).in_target_bin());
    assert!(!at([0.1975, 0.4025, 0.91]).in_target_bin());
    // In bin 1 where it starts: no.
    assert!(!at(base.can_pos).success());
}

#[test]
fn the_expert_places_the_can_and_a_miss_does_not() {
    let s = sim();
    let limits = RunLimits { max_steps: 300, stop_at_success: true, frame_size: None };
    for seed in 0..3 {
        let ep = s.episode(seed, CanBehaviour::Expert, Perturbation::default(), limits).unwrap();
        assert!(ep.success, "seed {seed}: {} steps, final {:?}", ep.rows.len(), &ep.final_state[..3]);
    }
    let miss = s.episode(0, CanBehaviour::Miss, Perturbation::default(), limits).unwrap();
    assert!(!miss.success);
}
