//! GPC's renderer against GPC's own frames, and evalharness's MuJoCo Push-T against GPC's
//! pymunk trajectories. The fixtures are frames and states GPC's environment produced
//! (`scripts/crosscheck_gpc_pusht.py --gpc CHECKOUT --write-fixtures`).

use super::*;
use crate::pusht::config::{RenderStyle, ResetRng};

const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/gpc_pusht");

fn fixture(name: &str) -> Vec<u8> {
    let path = format!("{FIXTURES}/{name}");
    std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// Rows of a fixture table (header dropped), as numbers.
fn table(name: &str) -> Vec<Vec<f64>> {
    let text = String::from_utf8(fixture(name)).expect("utf-8");
    text.lines().skip(1).map(|l| l.split('\t').map(|v| v.parse().expect("a number")).collect()).collect()
}

/// The scene of a `frames.tsv` row: the state and the goal.
fn scene(r: &[f64]) -> (PushTState, Pose2) {
    let state = PushTState { agent: [r[0], r[1]], agent_vel: [0.0; 2], block: Pose2::new(r[2], r[3], r[4]) };
    (state, Pose2::new(r[5], r[6], r[7]))
}

fn gpc_config() -> PushTConfig {
    let mut cfg = PushTConfig::default();
    cfg.render.style = RenderStyle::Gpc;
    cfg
}

#[test]
fn the_canvas_is_gpcs_pixel_for_pixel() {
    // canvas512.rle: GPC's 512² canvases of the first four fixture states, contact marks
    // off, as runs of (u32 little-endian length, r, g, b).
    let cfg = gpc_config();
    let rle = fixture("canvas512.rle");
    let mut want = Vec::new();
    for run in rle.chunks_exact(7) {
        let n = u32::from_le_bytes([run[0], run[1], run[2], run[3]]) as usize;
        want.extend(std::iter::repeat_n([run[4], run[5], run[6]], n).flatten());
    }
    let side = 512 * 512 * 3;
    assert_eq!(want.len(), 4 * side, "four canvases");
    for (i, r) in table("frames.tsv").iter().take(4).enumerate() {
        let (state, goal) = scene(r);
        let got = canvas(&cfg, &state, Some(&goal));
        let diff = got.pixels().chunks_exact(3).zip(want[i * side..(i + 1) * side].chunks_exact(3));
        let differ = diff.filter(|(a, b)| a != b).count();
        assert_eq!(differ, 0, "state {i}: {differ} canvas pixels differ from GPC's");
    }
}

#[test]
fn matches_gpcs_own_observation_frames() {
    // frames96.bin: what GPC's environment handed a policy in 24 states of pushing
    // episodes, its contact marks included. The bar: mean |difference| <= 0.5 per
    // channel and >= 99% of pixels within 8 levels.
    let cfg = gpc_config();
    let frames = fixture("frames96.bin");
    let rows = table("frames.tsv");
    let len = 96 * 96 * 3;
    assert_eq!(frames.len(), rows.len() * len);
    assert!(rows.len() >= 20);
    let (mut worst_mean, mut worst_within) = (0.0f64, 1.0f64);
    let mut out = vec![0u8; len];
    for (i, r) in rows.iter().enumerate() {
        let (state, goal) = scene(r);
        render_into(&cfg, &state, Some(&goal), 96, &mut out);
        let want = &frames[i * len..(i + 1) * len];
        let abs: Vec<u32> = out.iter().zip(want).map(|(&a, &b)| u32::from(a.abs_diff(b))).collect();
        let mean = f64::from(abs.iter().sum::<u32>()) / len as f64;
        let within = abs.chunks_exact(3).filter(|p| p.iter().all(|&d| d <= 8)).count() as f64 / (96.0 * 96.0);
        assert!(
            mean <= 0.5 && within >= 0.99,
            "state {i}: mean |diff| {mean:.3}, within 8 levels {within:.4}"
        );
        (worst_mean, worst_within) = (worst_mean.max(mean), worst_within.min(within));
    }
    println!(
        "GPC frames: {} states, worst mean |diff| {worst_mean:.4} per channel, worst share within 8 levels {worst_within:.5}",
        rows.len()
    );
}

#[test]
fn the_goal_free_frame_leaves_the_goal_out() {
    let cfg = gpc_config();
    let (state, goal) = scene(&table("frames.tsv")[0]);
    let (with, without) = (canvas(&cfg, &state, Some(&goal)), canvas(&cfg, &state, None));
    let black = |c: &Canvas| c.pixels().chunks_exact(3).filter(|p| *p == [0, 0, 0]).count();
    assert!(black(&with) > 1000 && black(&without) == 0);
}

#[test]
fn drift_against_gpcs_pymunk() {
    // trajectories.tsv: GPC's episodes of seeds 100010-100013 under logged actions. The
    // same seeds reset identically here (`reset.rng = "gpc-numpy"`); the same actions then
    // drive MuJoCo's Push-T. The agent follows the same PD law in both, so its path must
    // agree closely (measured at 2026-11-29: at most 3.30 units over 320 steps, where the
    // heavy MuJoCo disk is held up by the block it pushes; pymunk's is kinematic); the block's
    // drift (soft MuJoCo contacts against Chipmunk's impulses) is measured and printed.
    let mut cfg = PushTConfig::default();
    cfg.reset.rng = ResetRng::GpcNumpy;
    let model = crate::pusht::PushTPhysics::compile(&cfg).expect("model compiles");
    let mut env = crate::pusht::PushTEnv::new(model, &cfg);
    let rows = table("trajectories.tsv");
    let (mut agent_max, mut block_xy, mut block_th, mut n) = (0.0f64, 0.0f64, 0.0f64, 0);
    let mut at_end = Vec::new();
    // Block position drift after 10, 20, 40 and 80 actions, summed over the episodes.
    let mut by_step = [0.0f64; 4];
    for (k, r) in rows.iter().enumerate() {
        if r[1] == 0.0 {
            env.reset(r[0] as u64).expect("reset");
        }
        env.step([r[2], r[3]]).expect("step");
        let s = env.state();
        agent_max = agent_max.max((s.agent[0] - r[4]).hypot(s.agent[1] - r[5]));
        let dxy = (s.block.x - r[6]).hypot(s.block.y - r[7]);
        let dth = crate::pusht::geometry::wrap_angle(s.block.theta - r[8]).abs();
        (block_xy, block_th, n) = (block_xy + dxy, block_th + dth, n + 1);
        if let Some(i) = [9.0, 19.0, 39.0, 79.0].iter().position(|&t| t == r[1]) {
            by_step[i] += dxy;
        }
        if rows.get(k + 1).is_none_or(|next| next[1] == 0.0) {
            at_end.push(format!("seed {}: block {dxy:.1} units, {:.1} deg", r[0], dth.to_degrees()));
        }
    }
    let episodes = at_end.len() as f64;
    let by: Vec<String> =
        [10, 20, 40, 80].iter().zip(by_step).map(|(t, d)| format!("{t}: {:.1}", d / episodes)).collect();
    println!(
        "drift over {n} steps: agent at most {agent_max:.3} units; block on average {:.2} units and {:.2} deg; mean block drift after k actions ({}); after 80 steps: {}",
        block_xy / n as f64,
        (block_th / n as f64).to_degrees(),
        by.join(", "),
        at_end.join("; ")
    );
    assert!(agent_max < 5.0, "the agent's PD path differs from GPC's by {agent_max}");
}
