//! How a world model reads actions: each entry mapped linearly from its task's
//! range onto [-1, 1] before the U-Net's action embedding sees it.
//!
//! Push-T's models (all shipped ones) read 2-D absolute targets in world units
//! and normalise them as a' = 2a/511 − 1 (spec §1, world-model stats 0..511);
//! their configs carry no scale, and [`ActionScale::pusht`] is what that absence
//! means. A model of another task records its own scale (robomimic: 7 entries,
//! each already in [-1, 1]).

use serde::{Deserialize, Serialize};

use crate::error::SettingError;

/// Per-entry bounds of the actions a world model reads.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActionScale {
    /// Value of each entry that maps to -1.
    pub low: Vec<f32>,
    /// Value of each entry that maps to +1.
    pub high: Vec<f32>,
}

impl ActionScale {
    /// Push-T's world units, 0..511 on both axes.
    pub fn pusht() -> Self {
        Self { low: vec![0.0; 2], high: vec![511.0; 2] }
    }

    /// Entries per action.
    pub fn dim(&self) -> usize {
        self.low.len()
    }

    /// Appends the normalised entries of `action`: 2(a − low)/(high − low) − 1.
    /// With Push-T's scale this is 2a/511 − 1 exactly (a − 0 and 511 − 0 are exact).
    /// Callers check the action's size first ([`ActionScale::check`]).
    pub fn normalise_into(&self, action: &[f32], out: &mut Vec<f32>) {
        out.extend(
            action
                .iter()
                .zip(self.low.iter().zip(&self.high))
                .map(|(&a, (&lo, &hi))| 2.0 * (a - lo) / (hi - lo) - 1.0),
        );
    }

    /// Whether actions of `dim` entries can be read with this scale.
    ///
    /// # Errors
    /// [`SettingError::ActionWidth`] naming both sizes.
    pub fn check(&self, dim: usize) -> Result<(), SettingError> {
        if dim == self.dim() && self.high.len() == self.dim() {
            Ok(())
        } else {
            Err(SettingError::ActionWidth { given: dim, reads: self.dim() })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pusht_scale_is_two_a_over_511_minus_one() {
        let mut out = Vec::new();
        ActionScale::pusht().normalise_into(&[0.0, 511.0], &mut out);
        ActionScale::pusht().normalise_into(&[1.0, 255.5], &mut out);
        // 2·0/511 − 1 = −1; 2·511/511 − 1 = 1; 2·1/511 − 1 = −0.996086; 2·255.5/511 − 1 = 0.
        assert_eq!(out, vec![-1.0, 1.0, 2.0 * 1.0 / 511.0 - 1.0, 0.0]);
    }

    #[test]
    fn each_entry_has_its_own_range() {
        let s = ActionScale { low: vec![-1.0, 0.0, -0.5], high: vec![1.0, 4.0, 0.5] };
        let mut out = Vec::new();
        s.normalise_into(&[0.5, 1.0, 0.5], &mut out);
        // 2(0.5+1)/2 − 1 = 0.5; 2(1−0)/4 − 1 = −0.5; 2(0.5+0.5)/1 − 1 = 1.
        assert_eq!(out, vec![0.5, -0.5, 1.0]);
        assert!(s.check(3).is_ok());
        assert_eq!(s.check(2).unwrap_err().to_string(), "actions have 2 entries, the world model reads 3");
    }
}
