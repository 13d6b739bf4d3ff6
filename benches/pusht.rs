//! Push-T benchmarks (criterion).
//!
//! `cargo bench --bench pusht`; results are recorded in BENCHMARKS.md.

// criterion_group! generates undocumented functions.
#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use scenarios::pusht::expert::Expert;
use scenarios::pusht::mj_render::MujocoRenderer;
use scenarios::pusht::render::Rasterizer;
use scenarios::pusht::rollout::{Record, run_episode};
use scenarios::pusht::{Pose2, PushTConfig, PushTEnv, PushTPhysics, PushTState, initial_state};

fn pushing_state() -> PushTState {
    PushTState { agent: [150.0, 220.0], agent_vel: [0.0; 2], block: Pose2::new(256.0, 250.0, 0.0) }
}

fn physics(c: &mut Criterion) {
    let cfg = PushTConfig::default();
    let model = PushTPhysics::compile(&cfg).expect("model compiles");
    let mut sim = PushTPhysics::new(model, &cfg);
    let mut g = c.benchmark_group("pusht_physics");
    // One 0.01 s physics step (2 MuJoCo steps) while the agent pushes the block.
    g.bench_function("physics_step_in_contact", |b| {
        sim.set_state(&pushing_state());
        for _ in 0..5 {
            sim.control_step([200.0, 220.0]);
        }
        b.iter(|| sim.physics_step(black_box([200.0, 220.0])))
    });
    g.bench_function("control_step_free", |b| {
        sim.set_state(&PushTState {
            agent: [100.0, 100.0],
            agent_vel: [0.0; 2],
            block: Pose2::new(400.0, 400.0, 0.0),
        });
        b.iter(|| sim.control_step(black_box([120.0, 110.0])))
    });
    g.finish();
}

fn render(c: &mut Criterion) {
    let cfg = PushTConfig::default();
    let (state, goal) = initial_state(&cfg, 1).unwrap();
    let mut g = c.benchmark_group("pusht_render");
    for size in [96usize, 256] {
        let r = Rasterizer::with_size(&cfg, size);
        let mut buf = vec![0u8; r.frame_len()];
        g.bench_function(format!("raster_{size}"), |b| {
            b.iter(|| r.render_into(black_box(&state), &goal, &mut buf))
        });
    }
    // MuJoCo's OpenGL renderer (EGL; Mesa's software rasteriser on a machine without a GPU).
    let model = PushTPhysics::compile(&cfg).expect("model compiles");
    match MujocoRenderer::new(model, 96) {
        Ok(mut mj) => {
            g.bench_function("mujoco_96", |b| {
                b.iter(|| mj.render(black_box(&state), &goal).expect("renders"))
            });
        }
        Err(e) => eprintln!("skipping mujoco_96: {e}"),
    }
    g.finish();
}

fn expert(c: &mut Criterion) {
    let cfg = PushTConfig::default();
    let model = PushTPhysics::compile(&cfg).expect("model compiles");
    let mut env = PushTEnv::new(model, &cfg);
    let mut g = c.benchmark_group("pusht_expert");
    g.sample_size(10);
    // Seed 3: the expert succeeds after 87 control steps.
    g.bench_function("expert_episode_seed3", |b| {
        b.iter(|| {
            let mut ex = Expert::new(env.model(), &cfg);
            run_episode(&mut env, &mut ex, 3, 300, Record::default()).expect("episode runs")
        })
    });
    g.finish();
}

criterion_group!(benches, physics, render, expert);
criterion_main!(benches);
