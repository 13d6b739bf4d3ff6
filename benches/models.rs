//! Model throughput benchmarks (criterion): a policy decision and a world-model
//! chunk at batch 1 and batch 100 (`BENCH_WM_BATCHES=1,25,50,100` and
//! `BENCH_POLICY_BATCHES=1,8` for others; `BENCH_POLICY_THREADS=N` also times N decisions at
//! once on N threads, as `rank --jobs N` decides for N batches), on
//! the shipped checkpoints; and one chunk of
//! the paper's pixel-space U-Net (random weights: the cost does not depend on them; or an
//! imported model, `BENCH_PIXEL_WORLD_MODEL=DIR`).
//!
//! `cargo bench --bench models`; results are recorded in BENCHMARKS.md. The
//! checkpoints are read from `checkpoints/pusht/` (override with
//! `BENCH_POLICY=DIR` and `BENCH_WORLD_MODEL=DIR`). The pixel model runs at batch
//! 1 only unless `BENCH_PIXEL_BATCHES=1,100` asks for more (batch 100 is minutes per
//! iteration on a CPU); `BENCH_PIXEL_THREADS=N` also times N such chunks at once, one per
//! thread, as `rank --jobs N` runs N batches (an iteration is then N chunks). `world_model_objectives` times one chunk's U-Net passes of the
//! shipped model's architecture as DriftWorld (one pass) and as the K-step diffusion
//! baseline (`BENCH_DIFFUSION_STEPS`, default 10), random weights, at batch 1 unless
//! `BENCH_OBJECTIVE_BATCHES=1,100`. The device is `EVALHARNESS_DEVICE` (see
//! `nn::device`). `decoder` times the frame decoder alone, burn's
//! convolutions against the CPU kernels (`world_model::cpu_decoder`; Winograd's
//! algorithm since 2026-11-24, the direct 3x3 kernel under `EVALHARNESS_CONV=direct`), at
//! batch 1 and 50 on the shipped autoencoder (`BENCH_AUTOENCODER=DIR`);
//! `BENCH_DECODER_CHANNELS=8,16,32,32` adds a decoder of those widths (random
//! weights) on the direct kernels, to price a narrower decoder before training one.
//! `reward_predictor` times GPC's reward predictors reading one frame's pose, from an imported
//! judge folder (`BENCH_JUDGE=DIR`; skipped without one).

// criterion_group! generates undocumented functions.
#![allow(missing_docs)]

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use burn::tensor::{Device, Distribution, Tensor, TensorData};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use harness::judge::Judge;
use harness::policy::Observation;
use harness::rng::Rng;
use judges::folder::FrameJudge;
use policies::dir::{Expectations, checkpoint_dirs};
use policies::kinds::load_policy;
use world_model::autoencoder::AutoencoderConfig;
use world_model::codec::FrameCodec;
use world_model::cpu_decoder::CpuDecoder;
use world_model::model::{Objective, WorldModel, WorldModelConfig};
use world_model::train_ae::load_autoencoder;
use world_model::unet::UNetConfig;

const BATCHES: [usize; 2] = [1, 100];

fn path(var: &str, default: &str) -> PathBuf {
    std::env::var_os(var).map_or_else(|| PathBuf::from(default), PathBuf::from)
}

/// A grey 96 × 96 observation history of two frames.
fn observation() -> Observation {
    Observation {
        frames: vec![vec![200u8; 96 * 96 * 3]; 2],
        proprio: vec![vec![256.0, 256.0]; 2],
        robot: vec![Vec::new(); 2],
        size: 96,
        exact: None,
        native: None,
    }
}

fn policy(c: &mut Criterion) {
    let dir = path("BENCH_POLICY", "checkpoints/pusht/policies");
    let first = checkpoint_dirs(&dir).ok().and_then(|d| d.into_iter().next()).unwrap_or(dir);
    let device = nn::device::selected().expect("EVALHARNESS_DEVICE");
    let p = load_policy(&first, &Expectations::pusht(96), &device)
        .unwrap_or_else(|e| panic!("benchmark needs a policy checkpoint: {e}"));
    let mut g = c.benchmark_group("policy_decision");
    g.sample_size(10).measurement_time(Duration::from_secs(20));
    let batches = env_batches("BENCH_POLICY_BATCHES", &BATCHES);
    for &b in &batches {
        let obs = vec![observation(); b];
        let mut rngs: Vec<Rng> = (0..b as u64).map(Rng::new).collect();
        g.bench_with_input(BenchmarkId::from_parameter(b), &b, |bench, _| {
            bench.iter(|| black_box(p.act(&obs, &mut rngs).expect("policy acts")))
        });
    }
    // N decisions at once, one per thread, each for its own batch (as `rank --jobs N` decides
    // for N batches); an iteration ends when all are done.
    let threads = std::env::var("BENCH_POLICY_THREADS").ok().and_then(|v| v.parse().ok()).unwrap_or(1);
    for &b in batches.iter().filter(|_| threads > 1) {
        let obs = vec![observation(); b];
        g.bench_with_input(BenchmarkId::new(format!("x{threads}_threads"), b), &b, |bench, _| {
            bench.iter(|| {
                std::thread::scope(|scope| {
                    for t in 0..threads {
                        let (p, obs) = (&p, &obs);
                        scope.spawn(move || {
                            let mut rngs: Vec<Rng> =
                                (0..b as u64).map(|i| Rng::new(i + 1000 * t as u64)).collect();
                            black_box(p.act(obs, &mut rngs).expect("policy acts"))
                        });
                    }
                });
            })
        });
    }
    g.finish();
}

fn world_model(c: &mut Criterion) {
    let dir = path("BENCH_WORLD_MODEL", "checkpoints/pusht/world_model");
    let device = nn::device::selected().expect("EVALHARNESS_DEVICE");
    let wm = WorldModel::load(&dir, &device)
        .unwrap_or_else(|e| panic!("benchmark needs a world-model checkpoint: {e}"));
    chunk(c, "world_model_chunk", &wm, &env_batches("BENCH_WM_BATCHES", &BATCHES), 1);
}

/// The paper's pixel-space Push-T model (8,375,201 parameters), drifting, one pass per chunk,
/// in the layout of an imported official checkpoint (attention norms per frame); or the
/// world-model folder `BENCH_PIXEL_WORLD_MODEL` names (`evalharness import world-model`).
fn pixel_world_model(c: &mut Criterion) {
    let device = nn::device::selected().expect("device");
    let wm = match std::env::var("BENCH_PIXEL_WORLD_MODEL") {
        Ok(dir) => {
            WorldModel::load(std::path::Path::new(&dir), &device).expect("BENCH_PIXEL_WORLD_MODEL loads")
        }
        Err(_) => {
            let unet = UNetConfig::pusht_pixel().with_frame_attention_norm(Some(true));
            let cfg = WorldModelConfig::pixels(unet.clone(), 96);
            WorldModel::from_parts(cfg, FrameCodec::pixels(96), unet.init(&device), &device)
        }
    };
    let batches = env_batches("BENCH_PIXEL_BATCHES", &[1]);
    chunk(c, "world_model_pixel_chunk", &wm, &batches, 1);
    let threads = std::env::var("BENCH_PIXEL_THREADS").ok().and_then(|v| v.parse().ok()).unwrap_or(1);
    if threads > 1 {
        chunk(c, "world_model_pixel_chunk", &wm, &batches, threads);
    }
}

/// GPC's reward predictors as a judge reads a frame's pose (both ResNet-18 regressors on one
/// 96² frame), from an imported judge folder (`BENCH_JUDGE=DIR`; skipped without one).
fn reward_predictor(c: &mut Criterion) {
    let Ok(dir) = std::env::var("BENCH_JUDGE") else { return };
    let device = nn::device::selected().expect("EVALHARNESS_DEVICE");
    let judge = FrameJudge::load(std::path::Path::new(&dir), &device).expect("BENCH_JUDGE loads");
    let frame: Vec<u8> = (0..96 * 96 * 3).map(|i| (i * 7 % 256) as u8).collect();
    let mut g = c.benchmark_group("reward_predictor");
    g.bench_function("pose_96", |bench| bench.iter(|| black_box(judge.pose(&frame))));
    g.finish();
}

fn env_batches(var: &str, default: &[usize]) -> Vec<usize> {
    std::env::var(var)
        .ok()
        .map(|v| v.split(',').filter_map(|b| b.trim().parse().ok()).collect())
        .unwrap_or_else(|| default.to_vec())
}

/// DriftWorld's one pass per chunk against the K-step diffusion baseline on the same U-Net
/// (the shipped model's configuration plus the diffusion baseline's timestep embedding).
/// Only the U-Net passes are timed: decoding costs the same for both.
fn objectives(c: &mut Criterion) {
    let dir = path("BENCH_WORLD_MODEL", "checkpoints/pusht/world_model");
    let device = nn::device::selected().expect("EVALHARNESS_DEVICE");
    let shipped =
        WorldModelConfig::read(&dir).unwrap_or_else(|e| panic!("benchmark needs a world-model config: {e}"));
    let steps: usize = std::env::var("BENCH_DIFFUSION_STEPS").ok().and_then(|v| v.parse().ok()).unwrap_or(10);
    let batches = env_batches("BENCH_OBJECTIVE_BATCHES", &[1]);
    let mut g = c.benchmark_group("world_model_objectives");
    g.sample_size(10).measurement_time(Duration::from_secs(20));
    for (name, objective, sample_steps) in
        [("drifting", Objective::Drifting, 1), ("diffusion", Objective::Diffusion, steps)]
    {
        let mut unet = shipped.unet.clone();
        unet.timestep_embedding = objective == Objective::Diffusion;
        let cfg = WorldModelConfig { objective, sample_steps, unet: unet.clone(), ..shipped.clone() };
        let (ch, s) = (cfg.latents.channels, cfg.latents.size);
        let wm = WorldModel::from_parts(cfg, FrameCodec::pixels(s), unet.init(&device), &device);
        for &b in &batches {
            let history = Tensor::<5>::zeros([b, 4, ch, s, s], &device); // [b, 4, C, s, s]
            let anchor = Tensor::<4>::zeros([b, ch, s, s], &device); // [b, C, s, s]
            let actions = Tensor::<3>::zeros([b, 4, 2], &device); // [b, F, 2]
            let mut rngs: Vec<Rng> = (0..b as u64).map(Rng::new).collect();
            let id = BenchmarkId::new(format!("{name}_{sample_steps}_passes"), b);
            g.bench_with_input(id, &b, |bench, _| {
                bench.iter(|| {
                    black_box(
                        wm.predict(history.clone(), anchor.clone(), actions.clone(), &mut rngs).into_data(),
                    )
                })
            });
        }
    }
    g.finish();
}

fn decoder(c: &mut Criterion) {
    let dir = path("BENCH_AUTOENCODER", "checkpoints/pusht/autoencoder");
    let device = Device::flex();
    let (ae, cfg) = load_autoencoder(&dir, &device)
        .unwrap_or_else(|e| panic!("benchmark needs an autoencoder checkpoint: {e}"));
    let (ch, s) = (cfg.latent_channels, cfg.latent_size());
    let direct = CpuDecoder::new(&ae, s).unwrap_or_else(|e| panic!("{e}"));
    let mut g = c.benchmark_group("decoder");
    g.sample_size(10).measurement_time(Duration::from_secs(20));
    let narrow = std::env::var("BENCH_DECODER_CHANNELS").ok().map(|v| {
        let c: Vec<usize> =
            v.split(',').map(|x| x.trim().parse().expect("BENCH_DECODER_CHANNELS: 4 integers")).collect();
        let c: [usize; 4] = c.try_into().expect("BENCH_DECODER_CHANNELS: 4 integers");
        let ae = AutoencoderConfig { decoder_channels: Some(c), ..cfg.clone() }.init(&device);
        (v, CpuDecoder::new(&ae, s).unwrap_or_else(|e| panic!("{e}")))
    });
    for b in [1, 50] {
        let z = Tensor::<4>::random([b, ch, s, s], Distribution::Normal(0.0, 1.0), &device); // [b, C, s, s]
        let v: Vec<f32> = z.clone().into_data().try_to_vec().unwrap_or_default();
        g.bench_with_input(BenchmarkId::new("burn", b), &b, |bench, _| {
            bench.iter(|| black_box(ae.decode(z.clone()).into_data()))
        });
        g.bench_with_input(BenchmarkId::new("direct", b), &b, |bench, &b| {
            bench.iter(|| black_box(direct.decode(&v, b)))
        });
        if let Some((name, dec)) = &narrow {
            g.bench_with_input(BenchmarkId::new(format!("direct_{name}"), b), &b, |bench, &b| {
                bench.iter(|| black_box(dec.decode(&v, b)))
            });
        }
    }
    g.finish();
}

/// One world-model chunk at each batch size, on `threads` threads at once (each its own
/// chunk of the same size; an iteration ends when all are done).
fn chunk(c: &mut Criterion, group: &str, wm: &WorldModel, batches: &[usize], threads: usize) {
    let device = wm.device().clone();
    let mut g = c.benchmark_group(group);
    g.sample_size(10).measurement_time(Duration::from_secs(20));
    for &b in batches {
        // One chunk: encode nothing (latent history given), predict 4 frames, decode 2
        // (what a policy with obs horizon 2 sees per chunk in `rank`).
        let frames = Tensor::<4>::zeros([b, 3, 96, 96], &device);
        let z = wm.encode(frames); // [b, C, s, s]
        let [_, ch, s, _] = z.dims();
        let history = z.clone().reshape([b, 1, ch, s, s]).repeat_dim(1, 4); // [b, 4, C, s, s]
        let actions = Tensor::<3>::from_data(TensorData::new(vec![0f32; b * 4 * 2], [b, 4, 2]), &device);
        let one = || {
            let mut rngs: Vec<Rng> = (0..b as u64).map(Rng::new).collect();
            let out = wm.predict(history.clone(), z.clone(), actions.clone(), &mut rngs); // [b, 4, C, s, s]
            let last = out.slice([0..b, 2..4]).reshape([b * 2, ch, s, s]);
            black_box(wm.decode(last).into_data())
        };
        let name = if threads == 1 {
            "predict_4_decode_2".to_string()
        } else {
            format!("predict_4_decode_2_x{threads}_threads")
        };
        g.bench_with_input(BenchmarkId::new(name, b), &b, |bench, _| {
            bench.iter(|| {
                if threads == 1 {
                    one();
                } else {
                    std::thread::scope(|scope| {
                        for _ in 0..threads {
                            scope.spawn(one);
                        }
                    });
                }
            })
        });
    }
    g.finish();
}

criterion_group!(benches, policy, world_model, decoder, objectives, pixel_world_model, reward_predictor);
criterion_main!(benches);
