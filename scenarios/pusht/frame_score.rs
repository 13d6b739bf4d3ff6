//! Scoring Push-T from an image: what the world-model branch of `rank` has
//! instead of a simulator state.
//!
//! The goal pose is known (it is part of the episode's initial state), so the
//! scorer rasterises the goal T once (the fraction of each pixel inside it,
//! 4x4 supersampled) and reads the block from colour: a pixel's block fraction
//! is `(R − G) / 198`, clamped to [0, 1]. The block's fill (237, 39, 68) has
//! R − G = 198; white floor, black goal and grey walls have 0; the blue agent is
//! negative. Because the mixing with either white or black is linear, an
//! anti-aliased edge pixel half covered by the block reads 0.5. Then
//!
//! `coverage ≈ Σ_p goal(p)·block(p) / Σ_p goal(p)`.
//!
//! Its error against the exact polygon coverage is measured on real rendered
//! frames by `rank` and reported with every run.

use super::PushTConfig;
use super::colors::BlockPalette;
use super::geometry::{Pose2, TShape};

/// Block fraction of an RGB pixel of evalharness's own rendering (see the module docs and
/// [`BlockPalette::fraction`]).
pub fn block_fraction(px: &[u8]) -> f64 {
    BlockPalette::OWN.fraction(px)
}

/// Agent fraction of an RGB pixel: `(B − R) / 160`, clamped to [0, 1]. The agent's
/// RoyalBlue (65, 105, 225) has B − R = 160 and its inner disk (78, 126, 255) 177;
/// the floor, the goal, the walls and the block have B − R ≤ 0. Linear in a mix
/// with white or black, like [`block_fraction`].
pub fn agent_fraction(px: &[u8]) -> f64 {
    ((f64::from(px[2]) - f64::from(px[0])) / 160.0).clamp(0.0, 1.0)
}

pub use harness::judge::SceneCheck;

/// A coverage estimator for one goal pose.
#[derive(Clone, Debug)]
pub struct FrameScorer {
    /// Fraction of each pixel inside the goal T (row-major).
    goal: Vec<f64>,
    goal_sum: f64,
    /// The agent disk's area in pixels.
    agent_px: f64,
    size: usize,
    success_coverage: f64,
    /// The T and the goal pose, for scoring a pose read by another judge exactly.
    shape: TShape,
    goal_pose: Pose2,
    /// The block's colours in the frames this scorer reads (`[render] style`).
    palette: BlockPalette,
}

impl FrameScorer {
    /// A scorer for `goal` on `size x size` frames of the world in `cfg`.
    pub fn new(cfg: &PushTConfig, goal: &Pose2, size: usize) -> Self {
        let shape: TShape = cfg.shape();
        let scale = cfg.world.size / size as f64;
        let n = 4;
        let mut mask = vec![0.0; size * size];
        for (i, m) in mask.iter_mut().enumerate() {
            let (py, px) = ((i / size) as f64, (i % size) as f64);
            let mut inside = 0;
            for sy in 0..n {
                for sx in 0..n {
                    let w = [
                        (px + (sx as f64 + 0.5) / n as f64) * scale,
                        (py + (sy as f64 + 0.5) / n as f64) * scale,
                    ];
                    if shape.contains(goal.inverse_apply(w)) {
                        inside += 1;
                    }
                }
            }
            *m = f64::from(inside) / (n * n) as f64;
        }
        let goal_sum = mask.iter().sum();
        let agent_px = std::f64::consts::PI * (cfg.agent.radius / scale).powi(2);
        let success_coverage = cfg.task.success_coverage;
        let palette = BlockPalette::of(cfg.render.style);
        Self { goal: mask, goal_sum, agent_px, size, success_coverage, shape, goal_pose: *goal, palette }
    }

    /// Whether `frame` is an HWC RGB frame of this scorer's size with a non-empty goal.
    fn fits(&self, frame: &[u8]) -> bool {
        self.goal_sum > 0.0 && frame.len() == self.size * self.size * 3
    }

    /// Σ_p goal(p)·f(pixel p) / Σ_p goal(p): a per-pixel quantity averaged over the
    /// goal T (0 for a frame that does not fit).
    fn over_goal(&self, frame: &[u8], f: impl Fn(&[u8]) -> f64) -> f64 {
        if !self.fits(frame) {
            return 0.0;
        }
        let sum: f64 = self
            .goal
            .iter()
            .enumerate()
            .filter(|(_, g)| **g > 0.0)
            .map(|(i, g)| g * f(&frame[i * 3..i * 3 + 3]))
            .sum();
        sum / self.goal_sum
    }

    /// Σ_p f(pixel p) over the whole frame, divided by `area` pixels (0 for a frame
    /// that does not fit).
    fn over_frame(&self, frame: &[u8], f: impl Fn(&[u8]) -> f64, area: f64) -> f64 {
        if !self.fits(frame) {
            return 0.0;
        }
        frame.chunks_exact(3).map(f).sum::<f64>() / area
    }

    /// Estimated coverage of an HWC RGB frame.
    pub fn coverage(&self, frame: &[u8]) -> f64 {
        self.over_goal(frame, |px| self.palette.fraction(px)).clamp(0.0, 1.0)
    }

    /// Block pixels in the whole frame (Σ block fraction) as a fraction of the T's area
    /// in pixels (the goal T has the block's shape, so its mask sum is that area): ≈ 1
    /// on a real frame (less where the agent covers the block or the block leaves the
    /// floor), far below 1 when an imagined frame has lost the block, above 1 when it
    /// smears it. A health check of world-model frames, not a score.
    pub fn block_area(&self, frame: &[u8]) -> f64 {
        self.over_frame(frame, |px| self.palette.fraction(px), self.goal_sum)
    }

    /// How much of the goal T the frame still shows: Σ_p goal(p)·min(1, dark(p) +
    /// block(p)) / Σ_p goal(p), with dark = 1 − max(R, G, B)/255 (the goal is drawn
    /// black and only the block or the agent ever covers it). The goal never moves, so
    /// on a real frame this is ≈ 1 (less where the agent covers it); an imagined frame
    /// whose goal has faded or eroded scores far lower — the world model has lost the
    /// scene. A health check of world-model frames, not a score.
    pub fn goal_kept(&self, frame: &[u8]) -> f64 {
        let dark = |px: &[u8]| 1.0 - f64::from(px[0].max(px[1]).max(px[2])) / 255.0;
        self.over_goal(frame, |px| (dark(px) + self.palette.fraction(px)).min(1.0))
    }

    /// Agent pixels in the whole frame (Σ agent fraction) as a fraction of the agent
    /// disk's area in pixels, capped at 1. The agent is drawn over everything, so on a
    /// real frame this is ≈ 1 (a little less where its anti-aliased rim touches the
    /// block); an imagined frame in which the agent has vanished scores near 0 — the
    /// world model no longer shows what the policy does, so no contact can follow. The
    /// cap keeps a smeared agent (imagined blue over twice the disk, say) from hiding
    /// vanished ones in a policy's mean; the filmstrips show smearing. A health check
    /// of world-model frames, not a score.
    pub fn agent_kept(&self, frame: &[u8]) -> f64 {
        self.over_frame(frame, agent_fraction, self.agent_px).min(1.0)
    }

    /// All three health checks of a frame.
    pub fn scene(&self, frame: &[u8]) -> SceneCheck {
        SceneCheck(vec![
            ("block_area", self.block_area(frame)),
            ("goal_kept", self.goal_kept(frame)),
            ("agent_kept", self.agent_kept(frame)),
        ])
    }

    /// Estimated reward: clip(coverage / success threshold, 0, 1).
    pub fn reward(&self, frame: &[u8]) -> f64 {
        (self.coverage(frame) / self.success_coverage).clamp(0.0, 1.0)
    }

    /// Draws the goal T onto a frame rendered (or generated) without it, under the
    /// block and the agent as the renderer layers them: each pixel loses the white of
    /// its visible floor inside the goal, `out = px − 255·goal(p)·floor(p)`, where
    /// `floor(p) = min((G − g)/(255 − g), (R − 65)/190)` clamped to [0, 1] is the white part
    /// of a mix of floor with block red (fill green g: 39, or GPC's 34) or agent blue
    /// (R = 65). Exact on pixels
    /// fully inside or outside the goal; on the goal's anti-aliased rim where the block
    /// also passes it assumes the two cover independent parts of the pixel. A frame
    /// that does not fit is left as it is.
    pub fn draw_goal(&self, frame: &mut [u8]) {
        if !self.fits(frame) {
            return;
        }
        for (g, px) in self.goal.iter().zip(frame.chunks_exact_mut(3)) {
            if *g > 0.0 {
                let white = |v: u8, base: f64, span: f64| ((f64::from(v) - base) / span).clamp(0.0, 1.0);
                let g0 = f64::from(self.palette.fill[1]);
                let floor = white(px[1], g0, 255.0 - g0).min(white(px[0], 65.0, 190.0));
                let cut = 255.0 * g * floor;
                for c in px.iter_mut() {
                    *c = (f64::from(*c) - cut).clamp(0.0, 255.0).round() as u8;
                }
            }
        }
    }
}

/// Push-T's colour-mask judge of imagined frames: coverage read from the block's
/// red pixels over the goal, and the scene checks.
impl harness::judge::Judge for FrameScorer {
    fn score(&self, frame: &[u8]) -> f64 {
        self.coverage(frame)
    }

    fn scene(&self, frame: &[u8]) -> Option<SceneCheck> {
        Some(FrameScorer::scene(self, frame))
    }

    /// The exact coverage of the goal by a block at `pose` = [x, y, θ] (what GPC's
    /// evaluation computes from its reward predictors' pose); NaN for another length.
    fn score_pose(&self, pose: &[f64]) -> Option<f64> {
        let &[x, y, theta] = pose else { return Some(f64::NAN) };
        Some(super::geometry::coverage(&self.shape, &Pose2::new(x, y, theta), &self.goal_pose))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pusht::render::Rasterizer;
    use crate::pusht::{initial_state, score};

    fn cfg() -> PushTConfig {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("pusht.toml");
        PushTConfig::from_file(&path).unwrap()
    }

    #[test]
    fn colours_map_to_block_fractions() {
        assert_eq!(block_fraction(&[237, 39, 68]), 1.0);
        assert_eq!(block_fraction(&[255, 255, 255]), 0.0);
        assert_eq!(block_fraction(&[0, 0, 0]), 0.0);
        assert_eq!(block_fraction(&[65, 105, 225]), 0.0);
        assert_eq!((agent_fraction(&[65, 105, 225]), agent_fraction(&[78, 126, 255])), (1.0, 1.0));
        for other in [[255, 255, 255], [0, 0, 0], [237, 39, 68], [165, 28, 48], [211, 211, 211]] {
            assert_eq!(agent_fraction(&other), 0.0, "{other:?}");
        }
        // Half agent on white: (160·0.5 + 0) / 160 = 0.5, i.e. (160, 180, 240).
        assert!((agent_fraction(&[160, 180, 240]) - 0.5).abs() < 0.01);
        // Half block on black: (118.5 − 19.5) / 198 = 0.5.
        assert!((block_fraction(&[118, 19, 34]) - 0.5).abs() < 0.01);
    }

    /// The shipped scene in each rendering style.
    fn styles() -> [PushTConfig; 2] {
        let mut gpc = cfg();
        gpc.render.style = crate::pusht::config::RenderStyle::Gpc;
        [cfg(), gpc]
    }

    #[test]
    fn drawing_the_goal_onto_a_goal_free_frame_gives_the_rendered_frame() {
        for cfg in styles() {
            let raster = Rasterizer::new(&cfg);
            for seed in 0..8 {
                let (mut state, goal) = initial_state(&cfg, seed).unwrap();
                // Half the scenes with the block half over the goal (edges crossing its rim).
                if seed % 2 == 0 {
                    state.block = Pose2 { x: goal.x + 25.0, y: goal.y - 15.0, theta: goal.theta + 0.4 };
                }
                let scorer = FrameScorer::new(&cfg, &goal, raster.size());
                let with = raster.render(&state, &goal);
                let without = raster.render_without_goal(&state);
                assert!(!without.chunks_exact(3).any(|p| p == [0, 0, 0]), "seed {seed}: goal pixels left");
                let mut drawn = without.clone();
                scorer.draw_goal(&mut drawn);
                // Outside the goal's supersampled mask nothing changes, and the goal-free
                // render equals the full one there.
                let diffs: Vec<u8> = with.iter().zip(&drawn).map(|(a, b)| a.abs_diff(*b)).collect();
                for (i, g) in scorer.goal.iter().enumerate() {
                    if *g == 0.0 {
                        assert_eq!(
                            &drawn[i * 3..i * 3 + 3],
                            &with[i * 3..i * 3 + 3],
                            "seed {seed} pixel {i}"
                        );
                    }
                }
                // Inside, only rim pixels shared with the block or agent are approximate:
                // mean error below one grey level, coverage read the same.
                let mean = diffs.iter().map(|&d| f64::from(d)).sum::<f64>() / diffs.len() as f64;
                assert!(mean < 1.0, "seed {seed}: mean |difference| {mean:.3}");
                assert!((scorer.coverage(&drawn) - scorer.coverage(&with)).abs() < 1e-3, "seed {seed}");
            }
        }
    }

    #[test]
    fn block_area_of_an_empty_floor_is_zero_and_of_a_red_frame_is_large() {
        let cfg = cfg();
        let raster = Rasterizer::new(&cfg);
        let (_, goal) = initial_state(&cfg, 5).unwrap();
        let scorer = FrameScorer::new(&cfg, &goal, raster.size());
        let n = raster.size() * raster.size();
        assert_eq!(scorer.block_area(&vec![255; n * 3]), 0.0);
        assert_eq!(scorer.agent_kept(&vec![255; n * 3]), 0.0);
        // A white frame has lost the goal; a black one hides nothing.
        assert_eq!(scorer.goal_kept(&vec![255; n * 3]), 0.0);
        assert!((scorer.goal_kept(&vec![0; n * 3]) - 1.0).abs() < 1e-12);
        // Every pixel block-red: the frame's area over the T's (96² pixels against
        // the T's ~ (120·30 + 90·30) / (512/96)² ≈ 221 pixels: far above 1).
        let red: Vec<u8> = (0..n).flat_map(|_| [237, 39, 68]).collect();
        assert!(scorer.block_area(&red) > 10.0);
        assert_eq!(scorer.block_area(&red[..30]), 0.0, "a frame of the wrong size");
    }

    #[test]
    fn estimate_tracks_exact_coverage_on_rendered_frames() {
        for cfg in styles() {
            let style = cfg.render.style;
            let raster = Rasterizer::new(&cfg);
            let (mut state, goal) = initial_state(&cfg, 3).unwrap();
            let scorer = FrameScorer::new(&cfg, &goal, raster.size());
            // Slide the block onto the goal in steps: coverage goes from ~0 to 1.
            let start = state.block;
            for k in 0..=10 {
                let t = f64::from(k) / 10.0;
                state.block = Pose2 {
                    x: start.x + (goal.x - start.x) * t,
                    y: start.y + (goal.y - start.y) * t,
                    theta: start.theta + (goal.theta - start.theta) * t,
                };
                state.agent = [20.0, 20.0];
                let exact = score(&cfg, &state.block, &goal).coverage;
                let frame = raster.render(&state, &goal);
                let est = scorer.coverage(&frame);
                assert!(
                    (est - exact).abs() < 0.06,
                    "{style:?} step {k}: estimate {est:.3} vs exact {exact:.3}"
                );
                // The whole block is in view (the agent is in a corner): its pixels add up
                // to the T's area, plus the anti-aliased rim (measured 1.060–1.062 here).
                let area = scorer.block_area(&frame);
                // GPC's outlines are drawn outside the T as well as inside it, and its outline
                // reads 137/164 of the fill against 137/198 here (measured 1.081–1.131).
                let range =
                    if style == crate::pusht::config::RenderStyle::Gpc { 1.05..1.15 } else { 1.0..1.1 };
                assert!(range.contains(&area), "{style:?} step {k}: block area {area:.3}");
                // The goal shows wherever the block does not cover it (measured 0.937–0.989:
                // its anti-aliased rim mixes with the white floor).
                let goal_kept = scorer.goal_kept(&frame);
                assert!((0.9..=1.0).contains(&goal_kept), "{style:?} step {k}: goal kept {goal_kept:.3}");
            }
        }
    }

    #[test]
    fn the_agent_shows_wherever_it_is() {
        let cfg = cfg();
        let raster = Rasterizer::new(&cfg);
        let (mut state, goal) = initial_state(&cfg, 3).unwrap();
        let scorer = FrameScorer::new(&cfg, &goal, raster.size());
        // Positions over the world, a corner by the walls included. The disk covers
        // π·(15·96/512)² = 24.85 pixels; its anti-aliased rim on white counts in
        // proportion, so the sum comes out within a few percent of that (then capped at 1).
        let mut areas = Vec::new();
        for &(x, y) in &[(20.0, 20.0), (256.0, 20.0), (490.0, 490.0), (100.0, 300.0), (400.0, 150.0)] {
            state.agent = [x, y];
            let kept = scorer.scene(&raster.render(&state, &goal)).get("agent_kept").unwrap();
            areas.push(kept);
            assert!((0.95..=1.0).contains(&kept), "agent at ({x}, {y}): {kept:.3}");
        }
        // Touching the block, the rim pixels mixing blue with red count less (B − R of the
        // mix falls faster than on white), so the check reads a little under 1.
        state.agent = [state.block.x, state.block.y - 75.0 - 15.0];
        let touching = scorer.agent_kept(&raster.render(&state, &goal));
        assert!((0.8..=1.0).contains(&touching), "{touching:.3} ({areas:?})");
        // Without the agent (its pixels painted white) the check reads 0.
        let mut frame = raster.render(&state, &goal);
        frame.chunks_exact_mut(3).filter(|p| agent_fraction(p) > 0.0).for_each(|p| p.fill(255));
        assert_eq!(scorer.agent_kept(&frame), 0.0);
    }
}
