//! A 2-D anti-aliased rasteriser of the Push-T scene (the observation images).
//!
//! Push-T is planar, and the original environments draw it with a 2-D library
//! (pygame), so a rasteriser of the MuJoCo state is both faithful and ~100x
//! cheaper than GL rendering. Each pixel averages `supersample²` point samples;
//! each sample takes the colour of the topmost shape containing it, in the
//! order agent > block (with its outline) > goal > walls > background.
//! Colours follow the GPC renderer: white background, black goal T, red block
//! (1.2 x (198,33,57)) with a (165,28,48) 4-unit outline, a RoyalBlue agent disk
//! with a (78,126,255) inner disk, light-gray walls. y points down in the image.
//!
//! With `[render] style = "gpc"` the frames are GPC's own instead
//! ([`super::gpc_render`]); the rasteriser only dispatches.

use super::config::{PushTConfig, RenderStyle};
use super::geometry::{Pose2, TShape};
use super::physics::PushTState;

type Rgb = [u8; 3];

use super::colors::{AGENT, AGENT_INNER, AGENT_INNER_RADIUS, BACKGROUND, BlockPalette, GOAL, WALL};

/// Half width of the block's outline, world units (a 4-unit line centred on the edge).
const EDGE_HALF: f64 = 2.0;

/// Renders Push-T states to `size x size` RGB images (row-major, 3 bytes a pixel).
#[derive(Clone, Debug)]
pub struct Rasterizer {
    size: usize,
    supersample: usize,
    world: f64,
    shape: TShape,
    agent_radius: f64,
    wall_lo: f64,
    wall_hi: f64,
    wall_half: f64,
    /// The scene, when frames are drawn as GPC draws them.
    gpc: Option<std::sync::Arc<PushTConfig>>,
}

/// A body pose with its rotation precomputed.
struct Frame {
    x: f64,
    y: f64,
    s: f64,
    c: f64,
}

impl Frame {
    fn new(p: &Pose2) -> Self {
        let (s, c) = p.theta.sin_cos();
        Self { x: p.x, y: p.y, s, c }
    }

    fn to_body(&self, wx: f64, wy: f64) -> [f64; 2] {
        let (dx, dy) = (wx - self.x, wy - self.y);
        [dx * self.c + dy * self.s, -dx * self.s + dy * self.c]
    }
}

/// An axis-aligned box in world units.
struct Aabb {
    lo: [f64; 2],
    hi: [f64; 2],
}

impl Aabb {
    fn empty() -> Self {
        Self { lo: [f64::INFINITY; 2], hi: [f64::NEG_INFINITY; 2] }
    }

    fn grow(&mut self, x: f64, y: f64) {
        self.lo = [self.lo[0].min(x), self.lo[1].min(y)];
        self.hi = [self.hi[0].max(x), self.hi[1].max(y)];
    }

    fn pad(self, p: f64) -> Self {
        Self { lo: [self.lo[0] - p, self.lo[1] - p], hi: [self.hi[0] + p, self.hi[1] + p] }
    }

    fn contains(&self, x: f64, y: f64) -> bool {
        x >= self.lo[0] && x <= self.hi[0] && y >= self.lo[1] && y <= self.hi[1]
    }
}

fn disk_box(c: [f64; 2], r: f64) -> Aabb {
    Aabb { lo: [c[0] - r, c[1] - r], hi: [c[0] + r, c[1] + r] }
}

impl Rasterizer {
    /// A rasteriser with the scene's parameters.
    pub fn new(cfg: &PushTConfig) -> Self {
        Self::with_size(cfg, cfg.render.size as usize)
    }

    /// A rasteriser at another resolution (e.g. 512 for figures).
    pub fn with_size(cfg: &PushTConfig, size: usize) -> Self {
        Self {
            size,
            supersample: cfg.render.supersample as usize,
            world: cfg.world.size,
            shape: cfg.shape(),
            agent_radius: cfg.agent.radius,
            wall_lo: cfg.world.wall_inset,
            wall_hi: cfg.world.size - 1.0 - cfg.world.wall_inset,
            wall_half: cfg.world.wall_radius,
            gpc: (cfg.render.style == RenderStyle::Gpc).then(|| std::sync::Arc::new(cfg.clone())),
        }
    }

    /// Image side in pixels.
    pub fn size(&self) -> usize {
        self.size
    }

    /// Bytes of one image.
    pub fn frame_len(&self) -> usize {
        self.size * self.size * 3
    }

    /// Renders a new image.
    pub fn render(&self, state: &PushTState, goal: &Pose2) -> Vec<u8> {
        let mut out = vec![0u8; self.frame_len()];
        self.render_into(state, goal, &mut out);
        out
    }

    /// Renders the scene without the goal T (what a goal-free world model sees: the
    /// goal is static and known, so it is drawn back onto generated frames with
    /// [`super::frame_score::FrameScorer::draw_goal`] instead of being predicted).
    pub fn render_without_goal(&self, state: &PushTState) -> Vec<u8> {
        let mut out = vec![0u8; self.frame_len()];
        self.render_layers(state, None, &mut out);
        out
    }

    /// Renders into `out` (length [`Rasterizer::frame_len`]).
    ///
    /// # Panics
    /// If `out` has the wrong length (a programming error).
    pub fn render_into(&self, state: &PushTState, goal: &Pose2, out: &mut [u8]) {
        self.render_layers(state, Some(goal), out);
    }

    /// Renders into `out`, with the goal T or without it.
    ///
    /// Only pixels that an edge may cross are supersampled: a pixel whose centre is
    /// farther than its half diagonal from every boundary takes one sample, and a
    /// pixel outside every shape's bounding box is background without any test.
    ///
    /// # Panics
    /// If `out` has the wrong length (a programming error).
    fn render_layers(&self, state: &PushTState, goal: Option<&Pose2>, out: &mut [u8]) {
        assert_eq!(out.len(), self.frame_len(), "render buffer has the wrong size");
        if let Some(cfg) = &self.gpc {
            super::gpc_render::render_into(cfg, state, goal, self.size, out);
            return;
        }
        let n = self.supersample;
        let scale = self.world / self.size as f64;
        // Half diagonal of a pixel, in world units: the reach of an edge into it.
        let h = scale * std::f64::consts::FRAC_1_SQRT_2;
        let boxes = [
            self.shape_box(&state.block, EDGE_HALF + h),
            goal.map_or_else(Aabb::empty, |g| self.shape_box(g, h)),
            disk_box(state.agent, self.agent_radius + h),
        ];
        let block = Frame::new(&state.block);
        let goal = goal.map(Frame::new);
        let goal = goal.as_ref();
        let inv = 1.0 / (n * n) as f64;
        for py in 0..self.size {
            let cy = (py as f64 + 0.5) * scale;
            for px in 0..self.size {
                let cx = (px as f64 + 0.5) * scale;
                let o = (py * self.size + px) * 3;
                let near_wall = self.near_wall(cx, cy, h);
                if !near_wall && !boxes.iter().any(|b| b.contains(cx, cy)) {
                    out[o..o + 3].copy_from_slice(&BACKGROUND);
                    continue;
                }
                if !near_wall && !self.near_edge(cx, cy, h, state.agent, &block, goal) {
                    let c = self.sample(cx, cy, state.agent, &block, goal);
                    out[o..o + 3].copy_from_slice(&c);
                    continue;
                }
                let mut acc = [0.0f64; 3];
                for j in 0..n {
                    let wy = (py as f64 + (j as f64 + 0.5) / n as f64) * scale;
                    for i in 0..n {
                        let wx = (px as f64 + (i as f64 + 0.5) / n as f64) * scale;
                        let c = self.sample(wx, wy, state.agent, &block, goal);
                        for k in 0..3 {
                            acc[k] += f64::from(c[k]);
                        }
                    }
                }
                for k in 0..3 {
                    out[o + k] = (acc[k] * inv).round() as u8;
                }
            }
        }
    }

    /// Whether any shape boundary passes within `h` of world point (cx, cy).
    fn near_edge(
        &self,
        cx: f64,
        cy: f64,
        h: f64,
        agent: [f64; 2],
        block: &Frame,
        goal: Option<&Frame>,
    ) -> bool {
        let d = dist(cx - agent[0], cy - agent[1]);
        if (d - self.agent_radius).abs() < h || (d - AGENT_INNER_RADIUS).abs() < h {
            return true;
        }
        // The block has boundaries at EDGE_HALF outside and inside its outline.
        let b = block.to_body(cx, cy);
        let outside = self.shape.distance(b);
        if outside > 0.0 {
            if outside < EDGE_HALF + h {
                return true;
            }
        } else if within_inside(&self.shape, b, EDGE_HALF + h) {
            return true;
        }
        let Some(goal) = goal else { return false };
        let g = goal.to_body(cx, cy);
        let outside = self.shape.distance(g);
        if outside > 0.0 { outside < h } else { within_inside(&self.shape, g, h) }
    }

    /// The world-space bounding box of the T at `pose`, inflated by `pad`.
    fn shape_box(&self, pose: &Pose2, pad: f64) -> Aabb {
        let mut bb = Aabb::empty();
        for part in self.shape.world_parts(pose) {
            for c in part {
                bb.grow(c[0], c[1]);
            }
        }
        bb.pad(pad)
    }

    /// Whether a point is within `pad` of the wall band.
    fn near_wall(&self, wx: f64, wy: f64, pad: f64) -> bool {
        let (lo, hi, h) = (self.wall_lo, self.wall_hi, self.wall_half + pad);
        (wx - lo).abs() <= h || (wx - hi).abs() <= h || (wy - lo).abs() <= h || (wy - hi).abs() <= h
    }

    /// The colour of the topmost shape at world point (wx, wy).
    fn sample(&self, wx: f64, wy: f64, agent: [f64; 2], block: &Frame, goal: Option<&Frame>) -> Rgb {
        let d = dist(wx - agent[0], wy - agent[1]);
        if d <= AGENT_INNER_RADIUS {
            return AGENT_INNER;
        }
        if d <= self.agent_radius {
            return AGENT;
        }
        if let Some(c) = block_colour(&self.shape, block.to_body(wx, wy), &BlockPalette::OWN) {
            return c;
        }
        if goal.is_some_and(|g| self.shape.contains(g.to_body(wx, wy))) {
            return GOAL;
        }
        if self.on_wall(wx, wy) {
            return WALL;
        }
        BACKGROUND
    }

    /// Whether a point lies on one of the four wall segments (drawn 2 x wall_radius thick).
    fn on_wall(&self, wx: f64, wy: f64) -> bool {
        let (lo, hi, h) = (self.wall_lo, self.wall_hi, self.wall_half);
        let within = |v: f64| v >= lo - h && v <= hi + h;
        ((wx - lo).abs() <= h || (wx - hi).abs() <= h) && within(wy)
            || ((wy - lo).abs() <= h || (wy - hi).abs() <= h) && within(wx)
    }
}

/// The colour of the block (fill or outline, in `palette`) at a body-frame point, `None`
/// off the block. The outline is [`EDGE_HALF`] wide on either side of the boundary (GPC's
/// frames also outline the line where bar and stem meet; this is the union's outline).
pub fn block_colour(shape: &TShape, b: [f64; 2], palette: &BlockPalette) -> Option<Rgb> {
    if shape.contains(b) {
        return Some(if within_inside(shape, b, EDGE_HALF) { palette.edge } else { palette.fill });
    }
    (shape.distance(b) <= EDGE_HALF).then_some(palette.edge)
}

/// Whether an inside body-frame point lies within `e` of the T's boundary: a point
/// is deeper iff all four corners of the square of half side `e` around it are
/// inside (the T is a union of axis-aligned rectangles in its body frame).
fn within_inside(shape: &TShape, b: [f64; 2], e: f64) -> bool {
    [[-e, -e], [e, -e], [e, e], [-e, e]].iter().any(|o| !shape.contains([b[0] + o[0], b[1] + o[1]]))
}

/// The length of (dx, dy). Not `f64::hypot`: its overflow care is a libm call per
/// sample, a few percent of `rank`'s time, and world coordinates are far from overflow.
#[inline]
pub(crate) fn dist(dx: f64, dy: f64) -> f64 {
    (dx * dx + dy * dy).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pusht::colors::BLOCK;

    fn pixel(img: &[u8], size: usize, x: usize, y: usize) -> [u8; 3] {
        let o = (y * size + x) * 3;
        [img[o], img[o + 1], img[o + 2]]
    }

    #[test]
    fn colours_land_where_the_shapes_are() {
        let cfg = PushTConfig::default();
        let r = Rasterizer::new(&cfg);
        let state =
            PushTState { agent: [100.0, 400.0], agent_vel: [0.0; 2], block: Pose2::new(300.0, 200.0, 0.0) };
        let goal = Pose2::new(150.0, 150.0, 0.0);
        let img = r.render(&state, &goal);
        let s = 96;
        let px = |w: f64| (w * 96.0 / 512.0) as usize;
        // Agent centre (100, 400) -> pixel (18, 75): inner disk colour.
        assert_eq!(pixel(&img, s, px(100.0), px(400.0)), AGENT_INNER);
        // Block stem centre (300, 230) -> block fill.
        assert_eq!(pixel(&img, s, px(300.0), px(230.0)), BLOCK);
        // Goal stem centre (150, 180) -> black.
        assert_eq!(pixel(&img, s, px(150.0), px(180.0)), GOAL);
        // Empty middle of the floor -> white.
        assert_eq!(pixel(&img, s, px(400.0), px(420.0)), BACKGROUND);
        // A pixel straddling the stem's right edge (x = 315) is a blend, not a pure colour.
        let edge = pixel(&img, s, px(315.0), px(240.0));
        assert!(edge != BLOCK && edge != BACKGROUND, "{edge:?}");
    }

    /// Every pixel supersampled: what the fast path must reproduce exactly.
    fn render_brute_force(r: &Rasterizer, state: &PushTState, goal: &Pose2) -> Vec<u8> {
        let (block, goal) = (Frame::new(&state.block), Frame::new(goal));
        let n = r.supersample;
        let scale = r.world / r.size as f64;
        let mut out = vec![0u8; r.frame_len()];
        for py in 0..r.size {
            for px in 0..r.size {
                let mut acc = [0.0f64; 3];
                for j in 0..n {
                    for i in 0..n {
                        let wx = (px as f64 + (i as f64 + 0.5) / n as f64) * scale;
                        let wy = (py as f64 + (j as f64 + 0.5) / n as f64) * scale;
                        let c = r.sample(wx, wy, state.agent, &block, Some(&goal));
                        (0..3).for_each(|k| acc[k] += f64::from(c[k]));
                    }
                }
                let o = (py * r.size + px) * 3;
                (0..3).for_each(|k| out[o + k] = (acc[k] / (n * n) as f64).round() as u8);
            }
        }
        out
    }

    #[test]
    fn fast_path_matches_full_supersampling_exactly() {
        let cfg = PushTConfig::default();
        for size in [96, 61] {
            let r = Rasterizer::with_size(&cfg, size);
            for seed in 0..12 {
                let (mut state, goal) = super::super::initial_state(&cfg, seed).unwrap();
                // Park the agent against the block now and then, and near a wall.
                if seed % 3 == 0 {
                    state.agent = state.block.apply([0.0, 90.0]);
                }
                if seed % 4 == 1 {
                    state.agent = [12.0, 250.0];
                }
                assert_eq!(r.render(&state, &goal), render_brute_force(&r, &state, &goal), "seed {seed}");
            }
        }
    }

    #[test]
    fn rendering_is_deterministic() {
        let cfg = PushTConfig::default();
        let r = Rasterizer::new(&cfg);
        let (state, goal) = super::super::initial_state(&cfg, 3).unwrap();
        assert_eq!(r.render(&state, &goal), r.render(&state, &goal));
    }
}
