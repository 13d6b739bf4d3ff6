//! Push-T parameters, read from `scenarios/pusht.toml` (or a user's copy).
//!
//! The file is parsed into serde structs with `deny_unknown_fields`, then checked
//! field by field so that a bad value is reported with its dotted path.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::geometry::{Pose2, Rect, TShape};
use crate::error::ScenarioError;

/// The shipped default parameters (`scenarios/pusht.toml`).
pub const DEFAULT_TOML: &str = include_str!("../pusht.toml");

/// The shipped GPC-faithful scene (`scenarios/pusht_gpc.toml`, `--scenario pusht-gpc`):
/// GPC's resets and frames.
pub const GPC_TOML: &str = include_str!("../pusht_gpc.toml");

/// All Push-T parameters. See `scenarios/pusht.toml` for units and meaning.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(missing_docs)]
pub struct PushTConfig {
    pub name: String,
    pub world: WorldConfig,
    pub block: BlockConfig,
    pub agent: AgentConfig,
    pub timing: TimingConfig,
    pub reset: ResetConfig,
    pub task: TaskConfig,
    pub render: RenderConfig,
}

/// The square world and its walls.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(missing_docs)]
pub struct WorldConfig {
    pub size: f64,
    pub wall_inset: f64,
    pub wall_radius: f64,
}

/// The T block.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(missing_docs)]
pub struct BlockConfig {
    pub bar: Rect,
    pub stem: Rect,
    pub mass: f64,
    pub inertia: f64,
    pub damping_time: f64,
}

/// The disk agent and its PD law.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(missing_docs)]
pub struct AgentConfig {
    pub radius: f64,
    pub kp: f64,
    pub kd: f64,
    pub mass: f64,
}

/// Control and physics rates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(missing_docs)]
pub struct TimingConfig {
    pub control_hz: u32,
    pub physics_hz: u32,
    pub mujoco_substeps: u32,
}

/// Seeded reset distribution.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(missing_docs)]
pub struct ResetConfig {
    pub agent_range: [f64; 2],
    pub block_range: [f64; 2],
    pub goal_range: [f64; 2],
    pub min_agent_block_distance: f64,
    pub fixed_goal: bool,
    pub fixed_goal_pose: [f64; 3],
    /// The generator the reset draws from (absent: evalharness's own).
    #[serde(default, skip_serializing_if = "ResetRng::is_own")]
    pub rng: ResetRng,
}

/// The generator a Push-T reset draws from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ResetRng {
    /// ChaCha8 seeded from (seed, "pusht/reset"); the agent is also redrawn while its
    /// disk touches the T.
    #[default]
    Chacha,
    /// numpy's legacy `RandomState(seed)` in GPC's draw order, without the touch rule and
    /// with angles left unwrapped, so that seed s is GPC's episode s (seeds below 2^32).
    GpcNumpy,
}

impl ResetRng {
    /// Whether this is evalharness's own generator (the default, not written out).
    pub fn is_own(&self) -> bool {
        *self == Self::Chacha
    }
}

/// Episode length and success rule.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(missing_docs)]
pub struct TaskConfig {
    pub max_steps: u32,
    pub success_coverage: f64,
}

/// Observation rendering.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(missing_docs)]
pub struct RenderConfig {
    pub size: u32,
    pub supersample: u32,
    /// How frames are drawn (absent: evalharness's own).
    #[serde(default, skip_serializing_if = "RenderStyle::is_own")]
    pub style: RenderStyle,
}

/// How Push-T frames are drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RenderStyle {
    /// evalharness's anti-aliased rasteriser ([`super::render`]): `supersample²` samples a
    /// pixel, a (237, 39, 68) block with its outline around the whole T.
    #[default]
    Supersample,
    /// GPC's frames ([`super::gpc_render`]): pygame's aliased drawing on a canvas of the
    /// world's size, then OpenCV's bilinear resize; a (198, 34, 58) block with each of its
    /// two rectangles outlined. `supersample` is not used.
    Gpc,
}

impl RenderStyle {
    /// Whether this is evalharness's own style (the default, not written out).
    pub fn is_own(&self) -> bool {
        *self == Self::Supersample
    }
}

impl Default for PushTConfig {
    fn default() -> Self {
        // The shipped file is validated by a unit test, so this cannot fail at run time.
        Self::from_toml_str(DEFAULT_TOML, Path::new("scenarios/pusht.toml"))
            .unwrap_or_else(|e| unreachable!("shipped pusht.toml is invalid: {e}"))
    }
}

impl PushTConfig {
    /// The shipped GPC-faithful scene ([`GPC_TOML`]).
    ///
    /// # Errors
    /// Never for the shipped file (a unit test parses it); typed for the caller's `?`.
    pub fn gpc() -> Result<Self, ScenarioError> {
        Self::from_toml_str(GPC_TOML, Path::new("scenarios/pusht_gpc.toml"))
    }

    /// Parses and validates a Push-T config; `origin` names the file in errors.
    ///
    /// # Errors
    /// [`ScenarioError::Parse`] for malformed TOML or unknown keys,
    /// [`ScenarioError::InvalidField`] for out-of-range values.
    pub fn from_toml_str(text: &str, origin: &Path) -> Result<Self, ScenarioError> {
        let cfg: PushTConfig = toml::from_str(text)
            .map_err(|e| ScenarioError::Parse { path: origin.to_path_buf(), message: e.to_string() })?;
        cfg.validate(origin)?;
        Ok(cfg)
    }

    /// Reads, parses and validates a Push-T config file.
    ///
    /// # Errors
    /// [`ScenarioError::Io`] when the file cannot be read, and those of
    /// [`PushTConfig::from_toml_str`].
    pub fn from_file(path: &Path) -> Result<Self, ScenarioError> {
        let text = std::fs::read_to_string(path)
            .map_err(|source| ScenarioError::Io { path: path.to_path_buf(), source })?;
        Self::from_toml_str(&text, path)
    }

    /// The T shape.
    pub fn shape(&self) -> TShape {
        TShape { bar: self.block.bar, stem: self.block.stem }
    }

    /// The fixed goal pose (standard Push-T).
    pub fn fixed_goal(&self) -> Pose2 {
        let [x, y, t] = self.reset.fixed_goal_pose;
        Pose2::new(x, y, t)
    }

    /// Seconds per physics step.
    pub fn physics_dt(&self) -> f64 {
        1.0 / f64::from(self.timing.physics_hz)
    }

    /// Physics steps per control step.
    pub fn physics_per_control(&self) -> u32 {
        self.timing.physics_hz / self.timing.control_hz
    }

    fn validate(&self, origin: &Path) -> Result<(), ScenarioError> {
        let bad = |field: &str, reason: String| ScenarioError::InvalidField {
            path: origin.to_path_buf(),
            field: field.to_string(),
            reason,
        };
        let positive = [
            ("world.size", self.world.size),
            ("world.wall_radius", self.world.wall_radius),
            ("block.mass", self.block.mass),
            ("block.inertia", self.block.inertia),
            ("block.damping_time", self.block.damping_time),
            ("agent.radius", self.agent.radius),
            ("agent.kp", self.agent.kp),
            ("agent.kd", self.agent.kd),
            ("agent.mass", self.agent.mass),
            ("task.success_coverage", self.task.success_coverage),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(field, format!("must be a finite number > 0, got {v}")));
            }
        }
        if self.name != "pusht" {
            return Err(bad("name", format!("expected \"pusht\", got {:?}", self.name)));
        }
        for (field, r) in [("block.bar", self.block.bar), ("block.stem", self.block.stem)] {
            if !(r.x[0] < r.x[1] && r.y[0] < r.y[1]) {
                return Err(bad(field, format!("empty rectangle {r:?}")));
            }
        }
        let size = self.world.size;
        for (field, r) in [
            ("reset.agent_range", self.reset.agent_range),
            ("reset.block_range", self.reset.block_range),
            ("reset.goal_range", self.reset.goal_range),
        ] {
            if !(r[0] < r[1] && r[0] >= 0.0 && r[1] <= size) {
                return Err(bad(field, format!("must satisfy 0 <= lo < hi <= {size}, got {r:?}")));
            }
        }
        let t = &self.timing;
        if t.physics_hz == 0
            || t.control_hz == 0
            || t.mujoco_substeps == 0
            || !t.physics_hz.is_multiple_of(t.control_hz)
        {
            return Err(bad(
                "timing",
                format!(
                    "physics_hz ({}) must be a positive multiple of control_hz ({}), substeps >= 1",
                    t.physics_hz, t.control_hz
                ),
            ));
        }
        // Bounded so that an episode's cost stays finite: 1,000 physics steps a second of
        // 1,000 substeps each is already a million MuJoCo steps per simulated second.
        if t.physics_hz > 1000 || t.mujoco_substeps > 1000 || t.control_hz > 1000 {
            return Err(bad(
                "timing",
                format!(
                    "physics_hz ({}), control_hz ({}) and mujoco_substeps ({}) must each be at most 1000",
                    t.physics_hz, t.control_hz, t.mujoco_substeps
                ),
            ));
        }
        let d = self.reset.min_agent_block_distance;
        if !(d.is_finite() && d >= 0.0) {
            return Err(bad(
                "reset.min_agent_block_distance",
                format!("must be a finite number >= 0, got {d}"),
            ));
        }
        // Rejection sampling must find a state: try the first seed now, so an
        // impossible `reset` section is refused at load, not at some episode.
        if let Err(e) = super::initial_state(self, 0) {
            return Err(bad("reset.min_agent_block_distance", e.to_string()));
        }
        let sc = self.task.success_coverage;
        let steps_ok = (1..=100_000).contains(&self.task.max_steps);
        if !(steps_ok && sc.is_finite() && sc > 0.0 && sc <= 1.0) {
            return Err(bad("task", "max_steps in [1, 100000] and success_coverage in (0, 1]".into()));
        }
        if !(8..=1024).contains(&self.render.size) || !(1..=8).contains(&self.render.supersample) {
            return Err(bad("render", "size in 8..=1024, supersample in 1..=8".into()));
        }
        let w = self.world.size;
        if self.render.style == RenderStyle::Gpc && !(w.fract() == 0.0 && (8.0..=4096.0).contains(&w)) {
            return Err(bad(
                "render.style",
                format!(
                    "\"gpc\" draws on a canvas of the world's size, which must be a whole number of pixels in [8, 4096], got {w}"
                ),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_file_parses() {
        let cfg = PushTConfig::default();
        assert_eq!(cfg.shape(), TShape::GPC);
        assert_eq!(cfg.physics_per_control(), 10);
        assert!(!cfg.reset.fixed_goal);
    }

    #[test]
    fn unknown_key_is_rejected_with_its_name() {
        let text = DEFAULT_TOML.replace("[render]", "[render]\nblur = 3");
        let err = PushTConfig::from_toml_str(&text, Path::new("x.toml")).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("x.toml") && msg.contains("blur"), "{msg}");
    }

    #[test]
    fn zero_physics_rate_and_an_impossible_reset_are_refused() {
        // physics_hz = 0 is a multiple of every control_hz (0 = 0 x 10): it used to pass.
        let text = DEFAULT_TOML.replace("physics_hz = 100", "physics_hz = 0");
        assert_ne!(text, DEFAULT_TOML);
        let err = PushTConfig::from_toml_str(&text, Path::new("z.toml")).unwrap_err().to_string();
        assert!(err.contains("physics_hz (0)"), "{err}");
        // No agent position in the 512-unit world is 9000 units from the block.
        let text =
            DEFAULT_TOML.replace("min_agent_block_distance = 90.0", "min_agent_block_distance = 9000.0");
        assert_ne!(text, DEFAULT_TOML);
        let err = PushTConfig::from_toml_str(&text, Path::new("z.toml")).unwrap_err().to_string();
        assert!(err.contains("reset.min_agent_block_distance") && err.contains("seed 0"), "{err}");
        // At 92f9f2b any substep count was taken: 4e9 per physics step never finishes.
        let text = DEFAULT_TOML.replace("mujoco_substeps = 2 ", "mujoco_substeps = 4000000000 ");
        assert_ne!(text, DEFAULT_TOML);
        let err = PushTConfig::from_toml_str(&text, Path::new("z.toml")).unwrap_err().to_string();
        assert!(err.contains("mujoco_substeps (4000000000)"), "{err}");
    }

    #[test]
    fn the_shipped_gpc_scene_differs_from_the_default_only_in_reset_and_frames() {
        let (gpc, own) = (PushTConfig::gpc().unwrap(), PushTConfig::default());
        assert_eq!((gpc.render.style, gpc.reset.rng), (RenderStyle::Gpc, ResetRng::GpcNumpy));
        let mut back = gpc.clone();
        (back.render.style, back.reset.rng) = (own.render.style, own.reset.rng);
        assert_eq!(back, own);
    }

    #[test]
    fn the_gpc_style_is_read_and_needs_a_whole_pixel_world() {
        let text = DEFAULT_TOML.replace("[render]", "[render]\nstyle = \"gpc\"");
        let cfg = PushTConfig::from_toml_str(&text, Path::new("g.toml")).unwrap();
        assert_eq!(cfg.render.style, RenderStyle::Gpc);
        // The default style is not written out, so existing config.json files are unchanged.
        let own = toml::to_string(&PushTConfig::default()).unwrap();
        assert!(!own.contains("style"), "{own}");
        let text = text.replace("size = 512.0", "size = 512.5");
        let err = PushTConfig::from_toml_str(&text, Path::new("g.toml")).unwrap_err().to_string();
        assert!(err.contains("render.style") && err.contains("512.5"), "{err}");
    }

    #[test]
    fn bad_value_names_the_field() {
        let text = DEFAULT_TOML.replace("radius = 15.0", "radius = -1.0");
        let err = PushTConfig::from_toml_str(&text, Path::new("y.toml")).unwrap_err();
        assert!(err.to_string().contains("agent.radius"), "{err}");
    }
}
