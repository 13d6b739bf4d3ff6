//! Lift and Can benchmarks (criterion): the cost of one control step of physics
//! (25 MuJoCo steps under the OSC_POSE controller), of one agentview render, and
//! of an episode's reset (Lift composes and compiles its scene per episode for
//! the cube's size; Can copies one compiled model).
//!
//! The `frame` group times one 96 × 96 agentview frame of each task under each
//! rendering setting of `scenarios::robosuite::visual::Visual`, switched alone and
//! together (the mean pixel difference each makes is measured by the ignored test
//! `scenarios::robosuite::tests::frame_cost_per_visual_setting`).
//!
//! `cargo bench -p scenarios --bench robosuite` (it lives in `scenarios`, so it builds
//! only the simulator's dependencies); results are recorded in BENCHMARKS.md.

// criterion_group! generates undocumented functions.
#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use scenarios::can::{CanConfig, CanSim};
use scenarios::lift::{LiftConfig, LiftSim};
use scenarios::robosuite::renderer::release_renderer;
use scenarios::robosuite::visual::Visual;

fn lift(c: &mut Criterion) {
    let sim = LiftSim::new(LiftConfig::default()).expect("robosuite assets (scripts/setup.sh)");
    let mut g = c.benchmark_group("lift");
    // A control step with the gripper closing on nothing while the arm moves.
    let mut ep = sim.reset(1).expect("reset");
    let mut k = 0u32;
    g.bench_function("control_step", |b| {
        b.iter(|| {
            // Alternate directions so the arm stays near its start.
            k += 1;
            let s = if k % 20 < 10 { 0.3 } else { -0.3 };
            ep.step(black_box(&[s, -s, 0.0, 0.0, 0.0, 0.1 * s, 1.0])).expect("steps")
        })
    });
    for size in [96usize, 256] {
        g.bench_function(format!("render_agentview_{size}"), |b| {
            b.iter(|| ep.render(black_box(size)).expect("renders"))
        });
    }
    g.sample_size(10);
    g.bench_function("reset_compile", |b| b.iter(|| sim.reset(black_box(2)).expect("reset")));
    g.finish();
    release_renderer();
}

fn can(c: &mut Criterion) {
    let sim = CanSim::new(CanConfig::default()).expect("robosuite assets (scripts/setup.sh)");
    let mut g = c.benchmark_group("can");
    let mut ep = sim.reset(1).expect("reset");
    let mut k = 0u32;
    g.bench_function("control_step", |b| {
        b.iter(|| {
            k += 1;
            let s = if k % 20 < 10 { 0.3 } else { -0.3 };
            ep.arm_mut().step(black_box(&[s, -s, 0.0, 0.0, 0.0, 0.1 * s, 1.0])).expect("steps")
        })
    });
    g.bench_function("render_agentview_96", |b| {
        b.iter(|| ep.arm_mut().render(black_box(96)).expect("renders"))
    });
    g.bench_function("reset", |b| b.iter(|| sim.reset(black_box(2)).expect("reset")));
    g.finish();
    release_renderer();
}

/// The rendering settings the `frame` group compares, each alone, then together.
fn settings() -> Vec<(&'static str, Visual)> {
    let base = Visual::robosuite();
    vec![
        ("robosuite", base),
        ("offscreen_640x480", Visual { offscreen: [640, 480], ..base }),
        ("samples_0", Visual { samples: 0, ..base }),
        ("shadow_256", Visual { shadow_size: 256, ..base }),
        ("no_reflections", Visual { reflections: false, ..base }),
        (
            "all",
            Visual {
                offscreen: [96, 96],
                samples: 0,
                shadow_size: 256,
                reflections: false,
                render_size: None,
            },
        ),
    ]
}

fn frame(c: &mut Criterion) {
    let mut g = c.benchmark_group("frame");
    for (name, visual) in settings() {
        let lift = LiftSim::new(LiftConfig { visual, ..LiftConfig::default() }).expect("robosuite assets");
        let mut ep = lift.reset(1).expect("reset");
        g.bench_function(format!("lift_{name}"), |b| b.iter(|| ep.render(black_box(96)).expect("renders")));
        release_renderer();
        let can = CanSim::new(CanConfig { visual, ..CanConfig::default() }).expect("robosuite assets");
        let mut ep = can.reset(1).expect("reset");
        g.bench_function(format!("can_{name}"), |b| {
            b.iter(|| ep.arm_mut().render(black_box(96)).expect("renders"))
        });
        release_renderer();
    }
    g.finish();
}

criterion_group!(benches, lift, can, frame);
criterion_main!(benches);
