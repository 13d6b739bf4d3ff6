//! Reading the block and goal poses back from an observation image.
//!
//! A scripted policy that must act from what a learned policy sees (frames and
//! the agent position, no simulator state) needs the block and goal poses. Both
//! are T shapes of known geometry in distinctive colours (see
//! [`super::colors`]), so each pose is found in two steps:
//!
//! 1. **Moments.** The T's body origin is its centre of mass, so the weighted
//!    centroid of its pixels is the position. Its larger principal axis is the
//!    body y axis (variances 1232 vs 718 units² for the GPC T), and the third
//!    moment along that axis is positive (the long stem against the short, wide
//!    bar), which fixes the direction: θ = atan2(−d_x, d_y) for the axis d.
//! 2. **Fit.** A pattern search over (x, y, θ) minimises a squared difference
//!    over the pixels that say something about this T. The block: its coverage
//!    (4 x 4 samples a pixel, as the rasteriser) against the block fraction of
//!    every pixel the agent does not cover. The goal: the frame drawn with the
//!    fitted block on top (fill and outline, per sample) and the candidate goal
//!    below, against the observed colours, away from the agent — so the thin
//!    slivers of goal still visible around a block that nearly covers it, which
//!    are exactly what decides success, are used to the last sample.
//!    The search starts from the three best of 24 orientations at the moments'
//!    position and keeps the best fit, so a partly hidden goal (whose moments
//!    are biased) is still located.
//!
//! A goal too hidden for moments starts its fit from the block's pose; one
//! entirely hidden under the block stays there.

use super::PushTConfig;
use super::colors::{BACKGROUND, BlockPalette, GOAL};
use super::geometry::{Pose2, TShape, wrap_angle};
use super::render::block_colour;

/// What the perceiver read from a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Perceived {
    /// The block's pose.
    pub block: Pose2,
    /// The goal's pose.
    pub goal: Pose2,
}

/// Pixel maps of one frame.
struct Maps {
    /// Block fraction per pixel.
    block: Vec<f64>,
    /// Goal darkness per pixel (meaningful where `goal_known`).
    goal: Vec<f64>,
    /// Pixels whose colour is not covered by the block, the agent or a wall.
    goal_known: Vec<bool>,
    /// Pixels not covered by the agent.
    block_known: Vec<bool>,
}

/// Estimates block and goal poses from `size x size` frames of a scene.
#[derive(Clone, Debug)]
pub struct Perceiver {
    shape: TShape,
    size: usize,
    /// World units per pixel.
    scale: f64,
    /// The T's area in pixels.
    area_px: f64,
    /// Pixels next to the border (walls) that say nothing about the goal.
    border: usize,
    agent_radius: f64,
    /// The block's colours in the frames read (`[render] style`).
    palette: BlockPalette,
}

impl Perceiver {
    /// A perceiver for the scene in `cfg` at `size x size` pixels.
    pub fn new(cfg: &PushTConfig, size: usize) -> Self {
        let shape = cfg.shape();
        let scale = cfg.world.size / size as f64;
        let border = ((cfg.world.wall_inset + 2.0 * cfg.world.wall_radius) / scale).ceil() as usize + 1;
        let area_px = shape.area() / (scale * scale);
        let palette = BlockPalette::of(cfg.render.style);
        Self { shape, size, scale, area_px, border, agent_radius: cfg.agent.radius, palette }
    }

    /// Block and goal poses from an RGB frame (`size·size·3` bytes) with the agent
    /// at `agent` (world units; its disk is left out of the goal fit, so a wrong
    /// position costs nothing but a blind spot); `None` when the block is not visible
    /// (less than a third of its area in block colour) or the frame has the wrong length.
    pub fn perceive(&self, frame: &[u8], agent: Option<[f64; 2]>) -> Option<Perceived> {
        let n = self.size;
        if frame.len() != n * n * 3 {
            return None;
        }
        let maps = self.maps(frame);
        let block0 = self.moments(&maps.block, |_| true, self.area_px / 3.0)?;
        let window = self.window(&block0);
        let block = fit(block0, |p| self.error(p, &maps.block, &maps.block_known, window));
        let known = |i: usize| maps.goal_known[i];
        // Too little goal in view for moments: it is (nearly) under the block.
        let g0 = self.moments(&maps.goal, known, self.area_px / 20.0).unwrap_or(block);
        let scene = self.goal_scene(frame, &block, agent, self.window(&g0));
        let goal = fit(g0, |p| scene.error(p, frame, self));
        Some(Perceived { block, goal })
    }

    fn maps(&self, frame: &[u8]) -> Maps {
        let n = self.size;
        let mut m = Maps {
            block: vec![0.0; n * n],
            goal: vec![0.0; n * n],
            goal_known: vec![false; n * n],
            block_known: vec![true; n * n],
        };
        for i in 0..n * n {
            let px = &frame[i * 3..i * 3 + 3];
            let (r, g, b) = (f64::from(px[0]), f64::from(px[1]), f64::from(px[2]));
            let agent = b > r + 40.0;
            m.block[i] = self.palette.fraction(px);
            m.block_known[i] = !agent;
            let (y, x) = (i / n, i % n);
            let inner =
                (self.border..n - self.border).contains(&x) && (self.border..n - self.border).contains(&y);
            m.goal_known[i] = inner && !agent && m.block[i] < 0.02;
            m.goal[i] = (1.0 - r.max(g).max(b) / 255.0).clamp(0.0, 1.0);
        }
        m
    }

    /// The moments' pose of the mass in `w` over the pixels `use_px` admits;
    /// `None` below `min_mass` pixels.
    fn moments(&self, w: &[f64], use_px: impl Fn(usize) -> bool, min_mass: f64) -> Option<Pose2> {
        let n = self.size;
        let (mut m, mut sx, mut sy) = (0.0, 0.0, 0.0);
        for (i, &v) in w.iter().enumerate().filter(|&(i, _)| use_px(i)) {
            m += v;
            sx += v * (i % n) as f64;
            sy += v * (i / n) as f64;
        }
        if m < min_mass {
            return None;
        }
        let (cx, cy) = (sx / m, sy / m);
        let (mut a, mut b, mut c) = (0.0, 0.0, 0.0);
        for (i, &v) in w.iter().enumerate().filter(|&(i, _)| use_px(i)) {
            let (dx, dy) = ((i % n) as f64 - cx, (i / n) as f64 - cy);
            a += v * dx * dx;
            b += v * dx * dy;
            c += v * dy * dy;
        }
        // Direction of the larger principal axis.
        let phi = 0.5 * (2.0 * b).atan2(a - c);
        let mut d = [phi.cos(), phi.sin()];
        let skew: f64 = w
            .iter()
            .enumerate()
            .filter(|&(i, _)| use_px(i))
            .map(|(i, &v)| v * (((i % n) as f64 - cx) * d[0] + ((i / n) as f64 - cy) * d[1]).powi(3))
            .sum();
        if skew < 0.0 {
            d = [-d[0], -d[1]];
        }
        let s = self.scale;
        Some(Pose2::new((cx + 0.5) * s, (cy + 0.5) * s, (-d[0]).atan2(d[1])))
    }

    /// Squared error between the T's coverage at `pose` and `target` over the
    /// `known` pixels of `window` (`[x0, x1) x [y0, y1)`).
    fn error(&self, pose: &Pose2, target: &[f64], known: &[bool], window: [usize; 4]) -> f64 {
        let (n, s) = (self.size, self.scale);
        let (sin, cos) = pose.theta.sin_cos();
        let mut e = 0.0;
        for py in window[2]..window[3] {
            for px in window[0]..window[1] {
                let i = py * n + px;
                if !known[i] {
                    continue;
                }
                let mut inside = 0;
                for [ox, oy] in SAMPLES {
                    let wx = (px as f64 + ox) * s - pose.x;
                    let wy = (py as f64 + oy) * s - pose.y;
                    if self.shape.contains([wx * cos + wy * sin, -wx * sin + wy * cos]) {
                        inside += 1;
                    }
                }
                let d = f64::from(inside) / SAMPLES.len() as f64 - target[i];
                e += d * d;
            }
        }
        e
    }

    /// The pixels any candidate near `init` can reach: the T's reach (|(60, 75)| < 97
    /// units) plus the search's travel.
    fn window(&self, init: &Pose2) -> [usize; 4] {
        let reach = (97.0 + 40.0) / self.scale;
        let (cx, cy) = (init.x / self.scale, init.y / self.scale);
        let lo = |c: f64| (c - reach).floor().max(0.0) as usize;
        let hi = |c: f64| ((c + reach).ceil().max(0.0) as usize).min(self.size);
        [lo(cx), hi(cx), lo(cy), hi(cy)]
    }

    /// What the goal fit compares against, fixed for the frame: the block's colour
    /// at every sample (drawn over the goal) and which pixels are usable.
    fn goal_scene(
        &self,
        frame: &[u8],
        block: &Pose2,
        agent: Option<[f64; 2]>,
        window: [usize; 4],
    ) -> GoalScene {
        let (n, s) = (self.size, self.scale);
        let reach = self.agent_radius + s;
        let mut scene = GoalScene { pixels: Vec::new() };
        for py in window[2]..window[3] {
            for px in window[0]..window[1] {
                let i = py * n + px;
                let rgb = &frame[i * 3..i * 3 + 3];
                let inner = (self.border..n - self.border).contains(&px)
                    && (self.border..n - self.border).contains(&py);
                let (cx, cy) = ((px as f64 + 0.5) * s, (py as f64 + 0.5) * s);
                let near_agent = agent.is_some_and(|a| super::render::dist(cx - a[0], cy - a[1]) < reach);
                if !inner || near_agent || rgb[2] > rgb[0].saturating_add(40) {
                    continue;
                }
                let block_rgb = SAMPLES.map(|[ox, oy]| {
                    block_colour(
                        &self.shape,
                        block.inverse_apply([(px as f64 + ox) * s, (py as f64 + oy) * s]),
                        &self.palette,
                    )
                });
                scene.pixels.push((px, py, block_rgb));
            }
        }
        scene
    }
}

/// Sample offsets within a pixel: the rasteriser's 4 x 4 grid.
const SAMPLES: [[f64; 2]; 16] = {
    let mut s = [[0.0; 2]; 16];
    let mut k = 0;
    while k < 16 {
        s[k] = [((k % 4) as f64 + 0.5) / 4.0, ((k / 4) as f64 + 0.5) / 4.0];
        k += 1;
    }
    s
};

/// The block's colour (if any) at each sample of a pixel.
type BlockSamples = [Option<[u8; 3]>; 16];

/// The goal fit's fixed part: usable pixels `(x, y)` with the block's colour at
/// each of their samples.
struct GoalScene {
    pixels: Vec<(usize, usize, BlockSamples)>,
}

impl GoalScene {
    /// Squared colour error (channels in [0, 1]) between `frame` and the scene drawn
    /// with the goal at `goal`: each sample shows the block if it is there, else the
    /// goal's black or the floor's white.
    fn error(&self, goal: &Pose2, frame: &[u8], p: &Perceiver) -> f64 {
        let (n, s) = (p.size, p.scale);
        let mut e = 0.0;
        for (px, py, block) in &self.pixels {
            let mut acc = [0.0f64; 3];
            for (k, [ox, oy]) in SAMPLES.iter().enumerate() {
                let c = match block[k] {
                    Some(c) => c,
                    None if p
                        .shape
                        .contains(goal.inverse_apply([(*px as f64 + ox) * s, (*py as f64 + oy) * s])) =>
                    {
                        GOAL
                    }
                    None => BACKGROUND,
                };
                for ch in 0..3 {
                    acc[ch] += f64::from(c[ch]);
                }
            }
            let o = (py * n + px) * 3;
            for ch in 0..3 {
                let d = (acc[ch] / 16.0 - f64::from(frame[o + ch])) / 255.0;
                e += d * d;
            }
        }
        e
    }
}

/// Pattern search from the best few of 24 orientations at `init`'s position
/// (one of them `init`'s own); the best fit under `err`.
fn fit(init: Pose2, err: impl Fn(&Pose2) -> f64) -> Pose2 {
    let mut starts: Vec<(f64, Pose2)> = (0..24)
        .map(|k| {
            let p =
                Pose2::new(init.x, init.y, wrap_angle(init.theta + k as f64 * std::f64::consts::TAU / 24.0));
            (err(&p), p)
        })
        .collect();
    starts.sort_by(|a, b| a.0.total_cmp(&b.0));
    starts
        .iter()
        .take(3)
        .map(|&(_, p)| search(&err, p))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(init, |(p, _)| p)
}

/// Pattern search over (x, y, θ) from `init`: steps of 8 units and 0.16 rad, halved
/// whenever no move improves, until sub-pixel; the pose and its error.
fn search(error: &impl Fn(&Pose2) -> f64, init: Pose2) -> (Pose2, f64) {
    let mut best = init;
    let mut err = error(&best);
    let (mut step, mut turn) = (8.0, 0.16);
    while step > 0.2 {
        let mut improved = false;
        for (dx, dy, dt) in [
            (step, 0.0, 0.0),
            (-step, 0.0, 0.0),
            (0.0, step, 0.0),
            (0.0, -step, 0.0),
            (0.0, 0.0, turn),
            (0.0, 0.0, -turn),
        ] {
            let p = Pose2::new(best.x + dx, best.y + dy, wrap_angle(best.theta + dt));
            let e = error(&p);
            if e < err {
                (best, err, improved) = (p, e, true);
            }
        }
        if !improved {
            step /= 2.0;
            turn /= 2.0;
        }
    }
    (best, err)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pusht::initial_state;
    use crate::pusht::physics::PushTState;
    use crate::pusht::render::Rasterizer;

    fn cfg() -> PushTConfig {
        PushTConfig::from_file(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("pusht.toml")).unwrap()
    }

    fn errors(a: &Pose2, b: &Pose2) -> (f64, f64) {
        ((a.x - b.x).hypot(a.y - b.y), wrap_angle(a.theta - b.theta).abs().to_degrees())
    }

    #[test]
    fn reads_block_and_goal_poses_of_reset_frames() {
        let mut gpc = cfg();
        gpc.render.style = crate::pusht::config::RenderStyle::Gpc;
        for cfg in [cfg(), gpc] {
            reads_poses_in(&cfg);
        }
    }

    fn reads_poses_in(cfg: &PushTConfig) {
        let (raster, perceiver) = (Rasterizer::new(cfg), Perceiver::new(cfg, 96));
        let (mut worst_pos, mut worst_deg) = (0.0f64, 0.0f64);
        for seed in 0..20 {
            let (state, goal) = initial_state(cfg, seed).unwrap();
            let frame = raster.render(&state, &goal);
            let p = perceiver.perceive(&frame, Some(state.agent)).expect("the block is visible");
            for (est, truth) in [(p.block, state.block), (p.goal, goal)] {
                let (dp, da) = errors(&est, &truth);
                worst_pos = worst_pos.max(dp);
                worst_deg = worst_deg.max(da);
            }
        }
        // A pixel is 5.3 world units; the fit is sub-pixel.
        let style = cfg.render.style;
        eprintln!("{style:?}: worst errors {worst_pos:.2} units, {worst_deg:.2} deg");
        assert!(
            worst_pos < 2.5 && worst_deg < 2.0,
            "{style:?}: worst errors {worst_pos:.2} units, {worst_deg:.2} deg"
        );
    }

    /// From half hidden to nearly covered (the end of a successful push, where the
    /// goal shows only as slivers of anti-aliased pixels around the block).
    #[test]
    fn finds_a_goal_hidden_under_the_block() {
        let cfg = cfg();
        let (raster, perceiver) = (Rasterizer::new(&cfg), Perceiver::new(&cfg, 96));
        let goal = Pose2::new(250.0, 260.0, 0.6);
        for (dx, dy, dt) in
            [(25.0, 0.0, 0.0), (0.0, -30.0, 0.3), (12.0, 12.0, -0.5), (3.0, -2.0, 0.03), (-1.5, 1.0, -0.02)]
        {
            let block = Pose2::new(goal.x + dx, goal.y + dy, goal.theta + dt);
            let state = PushTState { agent: [60.0, 450.0], agent_vel: [0.0; 2], block };
            let p = perceiver.perceive(&raster.render(&state, &goal), Some(state.agent)).unwrap();
            let (dp, da) = errors(&p.goal, &goal);
            assert!(
                dp < 1.5 && da < 1.0,
                "offset ({dx}, {dy}, {dt}): goal off by {dp:.2} units, {da:.2} deg"
            );
            let (bp, ba) = errors(&p.block, &block);
            assert!(bp < 2.5 && ba < 2.0, "block off by {bp:.2} units, {ba:.2} deg");
        }
    }

    #[test]
    fn a_goal_under_the_block_is_the_block_and_no_block_is_none() {
        let cfg = cfg();
        let (raster, perceiver) = (Rasterizer::new(&cfg), Perceiver::new(&cfg, 96));
        let goal = Pose2::new(200.0, 300.0, -1.0);
        let state = PushTState { agent: [450.0, 60.0], agent_vel: [0.0; 2], block: goal };
        let p = perceiver.perceive(&raster.render(&state, &goal), Some(state.agent)).unwrap();
        let (dp, da) = errors(&p.goal, &goal);
        assert!(dp < 2.5 && da < 2.0, "{dp} {da}");
        let white = vec![255u8; 96 * 96 * 3];
        assert!(perceiver.perceive(&white, None).is_none());
        assert!(perceiver.perceive(&white[..10], None).is_none());
    }
}
