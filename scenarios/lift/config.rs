//! Lift's parameters: robosuite 1.5.2's `Lift` defaults, typed and checked.
//!
//! A scenario TOML (`name = "lift"`) may override any of them; an unknown key is refused with its
//! name (`deny_unknown_fields`).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::ScenarioError;
use crate::robosuite::read_named_toml;
use crate::robosuite::visual::{Visual, VisualPatch};

/// Everything that defines a Lift episode except the seed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LiftConfig {
    /// Table size (x, y, thickness), m.
    pub table_full_size: [f64; 3],
    /// Table friction: sliding, torsional, rolling.
    pub table_friction: [f64; 3],
    /// Table-top centre, m.
    pub table_offset: [f64; 3],
    /// Smallest cube half-size per axis, m (drawn uniformly per episode).
    pub cube_half_min: [f64; 3],
    /// Largest cube half-size per axis, m.
    pub cube_half_max: [f64; 3],
    /// Cube centre x range about the table centre, m.
    pub cube_x_range: [f64; 2],
    /// Cube centre y range about the table centre, m.
    pub cube_y_range: [f64; 2],
    /// Height of the cube's bottom above the table top at reset, m.
    pub cube_z_offset: f64,
    /// Standard deviation of the Gaussian noise on the arm's initial joints, rad.
    pub init_noise: f64,
    /// Height above the table top the cube's centre must exceed, m.
    pub success_height: f64,
    /// Control steps per episode (robomimic's rollout horizon).
    pub max_steps: usize,
    /// How agentview frames are rendered. The default is Lift's, [`Visual::cheap`], which its
    /// shipped models read (adapted to it by `train adapt`); a scenario file's `[visual]`
    /// replaces the settings it names. Always written out, so a dataset's or run's recorded
    /// config says which rendering made its frames.
    #[serde(deserialize_with = "lift_visual")]
    pub visual: Visual,
}

impl Default for LiftConfig {
    fn default() -> Self {
        Self {
            table_full_size: [0.8, 0.8, 0.05],
            table_friction: [1.0, 5e-3, 1e-4],
            table_offset: [0.0, 0.0, 0.8],
            cube_half_min: [0.020; 3],
            cube_half_max: [0.022; 3],
            cube_x_range: [-0.03, 0.03],
            cube_y_range: [-0.03, 0.03],
            cube_z_offset: 0.01,
            init_noise: 0.02,
            success_height: 0.04,
            max_steps: 400,
            visual: Visual::cheap(),
        }
    }
}

/// A `[visual]` section over Lift's default rendering.
fn lift_visual<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Visual, D::Error> {
    Ok(VisualPatch::deserialize(d)?.over(Visual::cheap()))
}

impl LiftConfig {
    /// Reads a scenario TOML: `name = "lift"` plus any of the fields to override.
    ///
    /// # Errors
    /// The file is unreadable, malformed, names another scenario, has an unknown
    /// key, or a value is out of range.
    pub fn from_file(path: &Path) -> Result<Self, ScenarioError> {
        let cfg: LiftConfig = read_named_toml(path, "lift")?;
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
        let finite3 = |v: [f64; 3]| v.iter().all(|x| x.is_finite());
        if self.table_full_size.iter().any(|v| !(v.is_finite() && *v > 0.0 && *v <= 10.0)) {
            return Err(bad("table_full_size", "every entry must be in (0, 10] m"));
        }
        if self.table_friction.iter().any(|v| !(v.is_finite() && *v >= 0.0 && *v <= 100.0)) {
            return Err(bad("table_friction", "every entry must be in [0, 100]"));
        }
        if !finite3(self.table_offset) || self.table_offset.iter().any(|v| v.abs() > 10.0) {
            return Err(bad("table_offset", "every entry must be finite, within 10 m of the origin"));
        }
        for i in 0..3 {
            let (lo, hi) = (self.cube_half_min[i], self.cube_half_max[i]);
            if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi && hi <= 0.2) {
                return Err(bad(
                    "cube_half_min",
                    "needs 0 < cube_half_min <= cube_half_max <= 0.2 m per axis",
                ));
            }
        }
        for (i, (field, r)) in
            [("cube_x_range", self.cube_x_range), ("cube_y_range", self.cube_y_range)].into_iter().enumerate()
        {
            if !(r[0].is_finite() && r[1].is_finite() && r[0] <= r[1]) {
                return Err(bad(field, "needs finite low <= high"));
            }
            // The whole cube stays on the table top at every draw.
            let half_table = self.table_full_size[i] / 2.0 - self.cube_half_max[i];
            if r[0] < -half_table || r[1] > half_table {
                return Err(bad(field, "puts the cube (partly) off the table"));
            }
        }
        if !(self.cube_z_offset.is_finite() && (0.0..=0.1).contains(&self.cube_z_offset)) {
            return Err(bad("cube_z_offset", "must be in [0, 0.1] m"));
        }
        if !(self.init_noise.is_finite() && (0.0..=0.5).contains(&self.init_noise)) {
            return Err(bad("init_noise", "must be in [0, 0.5] rad"));
        }
        // Success must be neither automatic (the cube's centre at rest is at least its
        // smallest half-height above the table) nor out of the arm's reach.
        let rest = self.cube_half_min[2];
        if !(self.success_height.is_finite() && self.success_height > rest + self.cube_z_offset)
            || self.success_height > 0.5
        {
            return Err(bad(
                "success_height",
                "must exceed the resting cube's centre height (cube_half_min[2] + cube_z_offset) \
                 and be at most 0.5 m, or success is automatic or impossible",
            ));
        }
        if !(1..=100_000).contains(&self.max_steps) {
            return Err(bad("max_steps", "must be in [1, 100000]"));
        }
        self.visual.validate(path)
    }

    /// The robot base for this table: robosuite's Panda `base_xpos_offset["table"]`
    /// (x = −0.16 − table length / 2) raised by the Rethink mount (0.912 m).
    pub fn robot_base(&self) -> [f64; 3] {
        [-0.16 - self.table_full_size[0] / 2.0, 0.0, 0.912]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unknown_key_is_refused_by_name() {
        let dir = std::env::temp_dir().join("evalharness-lift-config");
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("bad.toml");
        std::fs::write(&p, "name = \"lift\"\ncube_sise = 0.02\n").unwrap();
        let e = LiftConfig::from_file(&p).unwrap_err().to_string();
        assert!(e.contains("cube_sise"), "{e}");
        std::fs::write(&p, "name = \"lift\"\nmax_steps = 50\n").unwrap();
        assert_eq!(LiftConfig::from_file(&p).unwrap().max_steps, 50);
        std::fs::write(&p, "name = \"lift\"\nmax_steps = 0\n").unwrap();
        let e = LiftConfig::from_file(&p).unwrap_err().to_string();
        assert!(e.contains("max_steps"), "{e}");
    }

    #[test]
    fn values_that_make_success_automatic_or_impossible_are_refused_by_name() {
        // Each of these was accepted at 92f9f2b: success_height = -1 made every episode
        // a success, NaN none; a cube range of 1 m puts it off the 0.8 m table.
        let dir = std::env::temp_dir().join(format!("evalharness-lift-ranges-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("bad.toml");
        for (line, field) in [
            ("success_height = -1.0", "success_height"),
            ("success_height = nan", "success_height"),
            ("success_height = inf", "success_height"),
            ("success_height = 0.015", "success_height"),
            ("cube_x_range = [0.0, 1.0]", "cube_x_range"),
            ("cube_half_min = [-0.02, 0.02, 0.02]", "cube_half_min"),
            ("table_friction = [-1.0, 0.0, 0.0]", "table_friction"),
            ("table_offset = [0.0, 0.0, inf]", "table_offset"),
            ("cube_z_offset = -0.5", "cube_z_offset"),
            ("init_noise = 1e9", "init_noise"),
            ("max_steps = 1000000000", "max_steps"),
        ] {
            std::fs::write(&p, format!("name = \"lift\"\n{line}\n")).unwrap();
            let e = LiftConfig::from_file(&p).unwrap_err().to_string();
            assert!(e.contains(field), "{line}: {e}");
        }
        // The defaults pass: 0.04 > 0.020 + 0.01.
        LiftConfig::default().validate(&p).unwrap();
    }

    #[test]
    fn the_robot_stands_where_robosuite_puts_it() {
        // −0.16 − 0.8 / 2 = −0.56, as robosuite's model has robot0_base at (−0.56, 0, 0.912).
        assert_eq!(LiftConfig::default().robot_base(), [-0.56, 0.0, 0.912]);
    }
}
