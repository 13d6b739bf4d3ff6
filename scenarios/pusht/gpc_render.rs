//! GPC's Push-T frames (`[render] style = "gpc"`): what the official DriftWorld/GPC
//! environment hands its policies and world models, so that models trained on those
//! frames see the same pixels here.
//!
//! GPC draws with pygame on an aliased canvas of the world's size (512²), then shrinks
//! it with OpenCV's bilinear resize (`cv2.resize`, INTER_LINEAR) to the frame size. The
//! scene, in GPC's drawing order (pymunk's debug draw, measured on its environment):
//! 1. the goal T: bar and stem filled black, vertices rounded to canvas pixels;
//! 2. the block, bar then stem: each filled in (198, 34, 58) (1.2 × the block colour,
//!    rounded), then each of its four edges drawn as a "fat segment" of radius 2 in
//!    (165, 28, 48), so a dark line crosses the T where bar and stem meet;
//! 3. the agent: a RoyalBlue disk of radius 15, then a (78, 126, 255) disk of radius 11;
//! 4. the four walls, fat segments of radius 2 in LightGray, drawn last (on top).
//!
//! A fat segment is GPC's own construction: a 4-pixel line, a quadrilateral spanned by the
//! *absolute* components of the edge's normal (a slanted edge gets a skewed quad, as in
//! GPC), and a radius-2 disk at each end. Points are rounded half to even (Python's
//! `round`). The primitives are [`super::pygame_raster`].
//!
//! Not drawn: pymunk also marks each contact of its solver with a short red anti-aliased
//! segment; those depend on pymunk's contact set, which MuJoCo does not have. Measured
//! against GPC's own frames in `tests::matches_gpcs_own_observation_frames`.

use super::colors::BlockPalette;
use super::config::PushTConfig;
use super::geometry::{Pose2, Rect};
use super::physics::PushTState;
use super::pygame_raster::{Canvas, Rgb};
use harness::resize::resize_linear_u8;

/// GPC's block fill and outline (the palette's [`BlockPalette::GPC`]).
const BLOCK: Rgb = BlockPalette::GPC.fill;
const BLOCK_EDGE: Rgb = BlockPalette::GPC.edge;
/// The agent disk (RoyalBlue) and its inner disk (1.2 × RoyalBlue, clipped at 255).
const AGENT: Rgb = [65, 105, 225];
const AGENT_INNER: Rgb = [78, 126, 255];
const WALL: Rgb = [211, 211, 211];
const GOAL: Rgb = [0, 0, 0];
const BACKGROUND: Rgb = [255, 255, 255];
/// Radii GPC draws with: the block outline's and the walls' half width, and the
/// agent's inner disk (its radius minus 4).
const FAT: f64 = 2.0;
const INNER_INSET: f64 = 4.0;

/// Python's `round` of a float to an integer (half to even).
fn round(v: f64) -> i64 {
    v.round_ties_even() as i64
}

/// The four corners of a rectangle of the T, in the order pymunk keeps them:
/// (x0, y0), (x1, y0), (x1, y1), (x0, y1). The order decides the direction each edge
/// is walked in, which matters to the line's pixels.
fn corners(r: &Rect) -> [[f64; 2]; 4] {
    [[r.x[0], r.y[0]], [r.x[1], r.y[0]], [r.x[1], r.y[1]], [r.x[0], r.y[1]]]
}

fn to_px(p: [f64; 2]) -> [i64; 2] {
    [round(p[0]), round(p[1])]
}

/// GPC's `draw_fat_segment` from `a` to `b` (world = canvas units).
fn fat_segment(c: &mut Canvas, a: [f64; 2], b: [f64; 2], radius: f64, col: Rgb) {
    let (p1, p2) = (to_px(a), to_px(b));
    let width = round(radius * 2.0).max(1);
    c.thick_line(p1, p2, width, col);
    if width <= 2 {
        return;
    }
    let o = [(p2[1] - p1[1]).abs(), (p2[0] - p1[0]).abs()];
    if o == [0, 0] {
        return;
    }
    let scale = radius / ((o[0] * o[0] + o[1] * o[1]) as f64).sqrt();
    let o = [round(o[0] as f64 * scale), round(o[1] as f64 * scale)];
    let quad = [
        [p1[0] - o[0], p1[1] - o[1]],
        [p1[0] + o[0], p1[1] + o[1]],
        [p2[0] + o[0], p2[1] + o[1]],
        [p2[0] - o[0], p2[1] - o[1]],
    ];
    c.fill_polygon(&quad, col);
    c.fill_circle(p1, round(radius), col);
    c.fill_circle(p2, round(radius), col);
}

/// Draws the scene on a canvas of the world's size (GPC's 512²).
///
/// # Panics
/// Never for a validated config (the world size is checked to be a whole number of
/// pixels when the style is chosen).
pub fn canvas(cfg: &PushTConfig, state: &PushTState, goal: Option<&Pose2>) -> Canvas {
    let side = cfg.world.size as usize;
    let mut c = Canvas::new(side, BACKGROUND);
    let parts = [corners(&cfg.block.bar), corners(&cfg.block.stem)];
    if let Some(g) = goal {
        for part in &parts {
            let pts: Vec<[i64; 2]> = part.iter().map(|&v| to_px(g.apply(v))).collect();
            c.fill_polygon(&pts, GOAL);
        }
    }
    for part in &parts {
        let w: Vec<[f64; 2]> = part.iter().map(|&v| state.block.apply(v)).collect();
        let pts: Vec<[i64; 2]> = w.iter().map(|&p| to_px(p)).collect();
        c.fill_polygon(&pts, BLOCK);
        for i in 0..w.len() {
            fat_segment(&mut c, w[i], w[(i + 1) % w.len()], FAT, BLOCK_EDGE);
        }
    }
    let agent = to_px(state.agent);
    c.fill_circle(agent, round(cfg.agent.radius), AGENT);
    c.fill_circle(agent, round(cfg.agent.radius - INNER_INSET), AGENT_INNER);
    let (lo, hi) = (cfg.world.wall_inset, cfg.world.size - 1.0 - cfg.world.wall_inset);
    for (a, b) in [([lo, hi], [lo, lo]), ([lo, lo], [hi, lo]), ([hi, lo], [hi, hi]), ([lo, hi], [hi, hi])] {
        fat_segment(&mut c, a, b, cfg.world.wall_radius, WALL);
    }
    c
}

/// Renders a `size × size` frame into `out`: the canvas, resized as `cv2.resize` does.
///
/// # Panics
/// If `out` is not `size² × 3` bytes (a programming error).
pub fn render_into(cfg: &PushTConfig, state: &PushTState, goal: Option<&Pose2>, size: usize, out: &mut [u8]) {
    let c = canvas(cfg, state, goal);
    let side = c.side();
    if side == size {
        out.copy_from_slice(c.pixels());
        return;
    }
    let small = resize_linear_u8(c.pixels(), side, side, 3, size, size)
        .unwrap_or_else(|| unreachable!("a {side}² canvas resizes to any size"));
    out.copy_from_slice(&small);
}

#[cfg(test)]
#[path = "gpc_render_tests.rs"]
mod tests;
