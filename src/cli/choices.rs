//! The value sets of command-line options (clap value enums) that commands match
//! on. They live with the CLI so that the commands depend on it, never the other
//! way round.

/// Which renderer draws recorded frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RendererKind {
    /// The anti-aliased 2-D rasteriser (the observations).
    Raster,
    /// MuJoCo's OpenGL renderer beside the rasteriser (frames twice as wide).
    Mujoco,
}
