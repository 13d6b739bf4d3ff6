//! The Push-T scene's colours, shared by the rasteriser ([`super::render`]) and the
//! MuJoCo scene description ([`super::physics`]), so both draw the same scene, and the
//! block's colours of each rendering style, which the colour judge and the perceiver read.

use super::config::RenderStyle;

/// Floor.
pub const BACKGROUND: [u8; 3] = [255, 255, 255];
/// Goal T.
pub const GOAL: [u8; 3] = [0, 0, 0];
/// Block fill: 1.2 x (198, 33, 57).
pub const BLOCK: [u8; 3] = [237, 39, 68];
/// Block outline.
pub const BLOCK_EDGE: [u8; 3] = [165, 28, 48];
/// Agent disk (RoyalBlue).
pub const AGENT: [u8; 3] = [65, 105, 225];
/// Agent inner disk.
pub const AGENT_INNER: [u8; 3] = [78, 126, 255];
/// Walls.
pub const WALL: [u8; 3] = [211, 211, 211];
/// Radius of the agent's inner disk, world units.
pub const AGENT_INNER_RADIUS: f64 = 11.0;

/// The block's colours in one rendering style, and the block fraction they imply.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BlockPalette {
    /// Fill.
    pub fill: [u8; 3],
    /// Outline.
    pub edge: [u8; 3],
}

impl BlockPalette {
    /// evalharness's own rendering.
    pub const OWN: Self = Self { fill: BLOCK, edge: BLOCK_EDGE };
    /// GPC's rendering ([`super::gpc_render`]): the fill `min(1.2 × (165, 28, 48), 255)` in
    /// single precision, rounded; the outline the domain's block colour.
    pub const GPC: Self = Self { fill: [198, 34, 58], edge: [165, 28, 48] };

    /// The palette frames of `style` are drawn in.
    pub fn of(style: RenderStyle) -> Self {
        match style {
            RenderStyle::Supersample => Self::OWN,
            RenderStyle::Gpc => Self::GPC,
        }
    }

    /// Block fraction of an RGB pixel: `(R − G) / (R − G of the fill)`, clamped to [0, 1]
    /// (198 for evalharness's fill, 164 for GPC's). White floor, black goal and grey walls
    /// have R − G = 0, the blue agent a negative one, and mixing with white or black is
    /// linear, so a pixel half covered by the fill reads 0.5. The outline reads 137/198 or
    /// 137/164.
    pub fn fraction(&self, px: &[u8]) -> f64 {
        let full = f64::from(self.fill[0]) - f64::from(self.fill[1]);
        ((f64::from(px[0]) - f64::from(px[1])) / full).clamp(0.0, 1.0)
    }
}
