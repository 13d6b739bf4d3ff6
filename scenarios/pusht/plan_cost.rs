//! The cost a planner minimises on a predicted frame: how far the block is from
//! the goal, read from pixels.
//!
//! GPC-RANK (DriftWorld spec §11) scores each imagined action proposal on its
//! last predicted frame with learned pose regressors and a T-vertex distance. Here
//! the frame is read directly: every pixel's block fraction (see
//! [`block_fraction`]) weighs the distance from the pixel's centre to the goal T,
//!
//! `cost = Σ_p block(p)·d_goal(p) / Σ_p block(p)` (world units),
//!
//! the mean distance of the block's mass from the goal region. The block and the
//! goal are the same T, so the cost is 0 only when all of the block lies inside
//! the goal, i.e. when it covers it; unlike coverage it is dense (it still ranks
//! proposals whose block is nowhere near the goal), and unlike a pose fit it
//! degrades gracefully on the blurred blocks of a long imagined rollout. A frame
//! that has lost the block (less than [`MIN_BLOCK_AREA`] of the T's area in block
//! pixels) has no cost.

use super::PushTConfig;
use super::colors::BlockPalette;
use super::geometry::{Pose2, TShape};

/// Below this fraction of the T's area in block pixels, a frame shows no block to score.
pub const MIN_BLOCK_AREA: f64 = 0.25;

/// The goal-distance map of one goal pose.
#[derive(Clone, Debug)]
pub struct GoalDistance {
    /// Distance (world units) from each pixel centre to the goal T, row-major.
    dist: Vec<f64>,
    /// The T's area in pixels.
    t_px: f64,
    size: usize,
    /// The block's colours in the frames read (`[render] style`).
    palette: BlockPalette,
}

impl GoalDistance {
    /// The map for `goal` on `size x size` frames of the world in `cfg`.
    pub fn new(cfg: &PushTConfig, goal: &Pose2, size: usize) -> Self {
        let shape: TShape = cfg.shape();
        let scale = cfg.world.size / size as f64;
        let dist = (0..size * size)
            .map(|i| {
                let w = [((i % size) as f64 + 0.5) * scale, ((i / size) as f64 + 0.5) * scale];
                shape.distance(goal.inverse_apply(w))
            })
            .collect();
        Self { dist, t_px: shape.area() / (scale * scale), size, palette: BlockPalette::of(cfg.render.style) }
    }

    /// The mean distance (world units) of the frame's block pixels from the goal T;
    /// `None` for a frame of the wrong size or one that shows too little block.
    pub fn cost(&self, frame: &[u8]) -> Option<f64> {
        if frame.len() != self.size * self.size * 3 {
            return None;
        }
        let (mut mass, mut moment) = (0.0, 0.0);
        for (px, d) in frame.chunks_exact(3).zip(&self.dist) {
            let b = self.palette.fraction(px);
            mass += b;
            moment += b * d;
        }
        (mass >= MIN_BLOCK_AREA * self.t_px).then(|| moment / mass)
    }
}

impl harness::task::PlanCost for GoalDistance {
    fn cost(&self, frame: &[u8]) -> Option<f64> {
        GoalDistance::cost(self, frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pusht::initial_state;
    use crate::pusht::render::Rasterizer;

    fn setup() -> (PushTConfig, Rasterizer, Pose2, crate::pusht::physics::PushTState) {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("pusht.toml");
        let cfg = PushTConfig::from_file(&path).unwrap();
        let raster = Rasterizer::new(&cfg);
        let (state, goal) = initial_state(&cfg, 3).unwrap();
        (cfg, raster, goal, state)
    }

    #[test]
    fn zero_at_the_goal_and_growing_with_the_offset() {
        let (cfg, raster, goal, mut state) = setup();
        let map = GoalDistance::new(&cfg, &goal, raster.size());
        let mut at = |dx: f64| {
            state.block = Pose2::new(goal.x + dx, goal.y, goal.theta);
            state.agent = [goal.x + 200.0, goal.y + 200.0];
            map.cost(&raster.render(&state, &goal)).unwrap()
        };
        // On the goal only the anti-aliased rim pixels, whose centres lie within half a
        // pixel (512 / 96 / 2 = 2.7 units) of the T, weigh in: the mean stays far below that.
        let c0 = at(0.0);
        assert!(c0 < 1.0, "{c0}");
        // Shifted 60 units along x (twice the stem's width): most of the stem's mass is
        // outside, so the mean distance is tens of units; farther is larger still.
        let (c60, c120) = (at(60.0), at(120.0));
        assert!(c60 > 15.0 && c120 > c60 + 20.0, "{c60} {c120}");
    }

    #[test]
    fn no_cost_without_a_block() {
        let (cfg, raster, goal, _) = setup();
        let map = GoalDistance::new(&cfg, &goal, raster.size());
        let white = vec![255u8; raster.frame_len()];
        assert_eq!(map.cost(&white), None);
        assert_eq!(map.cost(&white[..30]), None);
    }
}
