//! Can's parameters: robosuite 1.5.2's `PickPlaceCan` defaults, typed and checked.
//!
//! A scenario TOML (`name = "can"`) may override any of them; an unknown key is
//! refused with its name (`deny_unknown_fields`).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::ScenarioError;
use crate::robosuite::read_named_toml;
use crate::robosuite::visual::{Visual, VisualPatch};

/// Everything that defines a Can episode except the seed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CanConfig {
    /// Centre of the bin the can starts in (its floor's centre), m.
    pub bin1_pos: [f64; 3],
    /// Centre of the bin with the four target quadrants, m.
    pub bin2_pos: [f64; 3],
    /// robosuite's `table_full_size` for PickPlace: the bins' footprint (x, y) and height, m.
    pub bin_size: [f64; 3],
    /// The can is placed at least this far (m) inside bin 1's edges, plus its radius.
    pub placement_margin: f64,
    /// The can's horizontal radius as robosuite computes it (the norm of its
    /// `horizontal_radius_site`, (0.025, 0.025)), m.
    pub can_radius: f64,
    /// The can's bottom below its origin (its `bottom_site`), m.
    pub can_bottom: f64,
    /// Standard deviation of the Gaussian noise on the arm's initial joints, rad.
    pub init_noise: f64,
    /// The gripper must be farther than this from the can for success, m:
    /// robosuite's 1 − tanh(10 d) < 0.6, i.e. d > atanh(0.4) / 10.
    pub release_distance: f64,
    /// Control steps per episode (robomimic's rollout horizon).
    pub max_steps: usize,
    /// How agentview frames are rendered. The default is Can's, [`Visual::no_reflections`],
    /// which its shipped models read (adapted from robosuite's rendering, 2026-12-03); a
    /// scenario file's `[visual]` replaces the settings it names. Always written out, so a
    /// dataset's or run's recorded config says which rendering made its frames.
    #[serde(deserialize_with = "can_visual")]
    pub visual: Visual,
}

impl Default for CanConfig {
    fn default() -> Self {
        Self {
            bin1_pos: [0.1, -0.25, 0.8],
            bin2_pos: [0.1, 0.28, 0.8],
            bin_size: [0.39, 0.49, 0.82],
            placement_margin: 0.05,
            can_radius: (0.025f64 * 0.025 * 2.0).sqrt(),
            can_bottom: -0.06,
            init_noise: 0.02,
            release_distance: 0.4f64.atanh() / 10.0,
            max_steps: 400,
            visual: Visual::no_reflections(),
        }
    }
}

/// A `[visual]` section over Can's default rendering.
fn can_visual<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Visual, D::Error> {
    Ok(VisualPatch::deserialize(d)?.over(Visual::no_reflections()))
}

impl CanConfig {
    /// Reads a scenario TOML: `name = "can"` plus any of the fields to override.
    ///
    /// # Errors
    /// The file is unreadable, malformed, names another scenario, has an unknown
    /// key, or a value is out of range.
    pub fn from_file(path: &Path) -> Result<Self, ScenarioError> {
        let cfg: CanConfig = read_named_toml(path, "can")?;
        cfg.validate(path)?;
        Ok(cfg)
    }

    /// Checks ranges.
    ///
    /// # Errors
    /// [`ScenarioError::InvalidField`] naming the field.
    pub fn validate(&self, path: &Path) -> Result<(), ScenarioError> {
        let bad = |field: &str, reason: &str| ScenarioError::InvalidField {
            path: path.into(),
            field: field.to_string(),
            reason: reason.into(),
        };
        for (field, v) in [("bin1_pos", self.bin1_pos), ("bin2_pos", self.bin2_pos)] {
            if v.iter().any(|x| !(x.is_finite() && x.abs() <= 10.0)) {
                return Err(bad(field, "every entry must be finite, within 10 m of the origin"));
            }
        }
        if self.bin_size.iter().any(|v| !(v.is_finite() && *v > 0.0 && *v <= 10.0)) {
            return Err(bad("bin_size", "every entry must be in (0, 10] m"));
        }
        if !(self.can_radius.is_finite() && self.can_radius > 0.0 && self.can_radius <= 0.2) {
            return Err(bad("can_radius", "must be in (0, 0.2] m"));
        }
        if !(self.can_bottom.is_finite() && (-0.3..=0.0).contains(&self.can_bottom)) {
            return Err(bad("can_bottom", "must be in [-0.3, 0] m (the bottom is below the can's origin)"));
        }
        if !(self.placement_margin.is_finite() && self.placement_margin >= 0.0) {
            return Err(bad("placement_margin", "must be >= 0"));
        }
        let room = [0, 1].map(|i| self.bin_size[i] / 2.0 - self.placement_margin - self.can_radius);
        if room.iter().any(|r| !(r.is_finite() && *r >= 0.0)) {
            return Err(bad("placement_margin", "leaves no room for the can in bin 1"));
        }
        // Success needs the can inside bin 2's quadrant and not in bin 1 at reset: bins
        // that overlap would make some resets successes before any action.
        let apart = (0..2).any(|i| (self.bin1_pos[i] - self.bin2_pos[i]).abs() >= self.bin_size[i]);
        if !apart {
            return Err(bad("bin2_pos", "overlaps bin 1, so a can could start in the target quadrant"));
        }
        if !(self.init_noise.is_finite() && (0.0..=0.5).contains(&self.init_noise)) {
            return Err(bad("init_noise", "must be in [0, 0.5] rad"));
        }
        if !(self.release_distance.is_finite() && self.release_distance > 0.0 && self.release_distance <= 0.5)
        {
            return Err(bad("release_distance", "must be in (0, 0.5] m"));
        }
        if !(1..=100_000).contains(&self.max_steps) {
            return Err(bad("max_steps", "must be in [1, 100000]"));
        }
        self.visual.validate(path)
    }

    /// The robot base: robosuite's Panda `base_xpos_offset["bins"]` (−0.5, −0.1)
    /// raised by the Rethink mount (0.912 m).
    pub fn robot_base(&self) -> [f64; 3] {
        [-0.5, -0.1, 0.912]
    }

    /// Bin 2's quadrant `i` (0 milk, 1 bread, 2 cereal, 3 can) as robosuite's
    /// `PickPlace.not_in_bin` bounds it: ([x low, x high], [y low, y high]).
    pub fn quadrant(&self, i: usize) -> ([f64; 2], [f64; 2]) {
        let mut x = self.bin2_pos[0];
        let mut y = self.bin2_pos[1];
        if i == 0 || i == 2 {
            x -= self.bin_size[0] / 2.0;
        }
        if i < 2 {
            y -= self.bin_size[1] / 2.0;
        }
        ([x, x + self.bin_size[0] / 2.0], [y, y + self.bin_size[1] / 2.0])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_can_quadrant_and_release_distance_are_robosuites() {
        let c = CanConfig::default();
        // Quadrant 3: x from bin 2's centre 0.1 to 0.1 + 0.39 / 2 = 0.295; y from
        // 0.28 to 0.28 + 0.49 / 2 = 0.525.
        let (x, y) = c.quadrant(3);
        assert!((x[0] - 0.1).abs() < 1e-12 && (x[1] - 0.295).abs() < 1e-12, "{x:?}");
        assert!((y[0] - 0.28).abs() < 1e-12 && (y[1] - 0.525).abs() < 1e-12, "{y:?}");
        // Its centre is robosuite's VisualCan position (0.1975, 0.4025).
        assert!(((x[0] + x[1]) / 2.0 - 0.1975).abs() < 1e-12);
        assert!(((y[0] + y[1]) / 2.0 - 0.4025).abs() < 1e-12);
        // atanh(0.4) = ½ ln(1.4 / 0.6) = 0.42365: the gripper must be 4.24 cm away.
        assert!((c.release_distance - 0.042365).abs() < 1e-6, "{}", c.release_distance);
    }

    #[test]
    fn an_unknown_key_is_refused_by_name() {
        let dir = std::env::temp_dir().join("evalharness-can-config");
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("bad.toml");
        std::fs::write(&p, "name = \"can\"\nbin3_pos = [0.0, 0.0, 0.0]\n").unwrap();
        let e = CanConfig::from_file(&p).unwrap_err().to_string();
        assert!(e.contains("bin3_pos"), "{e}");
    }

    #[test]
    fn values_that_make_success_automatic_or_impossible_are_refused_by_name() {
        // Each was accepted at 92f9f2b (negative radii, NaN or overlapping bins).
        let dir = std::env::temp_dir().join(format!("evalharness-can-ranges-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("bad.toml");
        for (line, field) in [
            ("can_radius = -0.03", "can_radius"),
            ("can_bottom = nan", "can_bottom"),
            ("bin2_pos = [0.1, -0.25, 0.8]", "bin2_pos"),
            ("bin1_pos = [inf, 0.0, 0.8]", "bin1_pos"),
            ("release_distance = -1.0", "release_distance"),
            ("placement_margin = -0.5", "placement_margin"),
            ("init_noise = 3.0", "init_noise"),
            ("max_steps = 1000000000", "max_steps"),
        ] {
            std::fs::write(&p, format!("name = \"can\"\n{line}\n")).unwrap();
            let e = CanConfig::from_file(&p).unwrap_err().to_string();
            assert!(e.contains(field), "{line}: {e}");
        }
        // The defaults pass: the bins' centres are 0.53 m apart in y, more than 0.49.
        CanConfig::default().validate(&p).unwrap();
    }
}
