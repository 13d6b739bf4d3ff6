//! The Push-T scene's colours, shared by the rasteriser ([`super::render`]) and the
//! MuJoCo scene description ([`super::physics`]), so both draw the same scene.

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
