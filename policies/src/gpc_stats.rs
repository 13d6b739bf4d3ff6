//! The normalisation statistics of an imported GPC Push-T policy. GPC's checkpoints do
//! not store them: its evaluation script sets the agent position's and the action's
//! ranges ([`pusht_normalisation`]). A policy trained on other data comes with a
//! `--stats` file instead ([`read_statistics`]), checked against the networks' widths.

use std::path::Path;

use nn::ImportError;

use crate::diffusion::{Normalisation, Range};

/// The statistics GPC's Push-T evaluation normalises with (`policy_eval.py`): the
/// agent position's range in pixels of the 512² window, and the action's.
#[must_use]
pub fn pusht_normalisation() -> Normalisation {
    Normalisation {
        agent_pos: Range { min: vec![9.897_889, 9.635_92], max: vec![499.517, 499.004_88] },
        action: Range { min: vec![2.0, 2.0], max: vec![511.0, 511.0] },
    }
}

/// Reads a statistics file (`{"agent_pos": {"min", "max"}, "action": {"min", "max"}}`)
/// for a policy whose networks read `proprio` proprioceptive entries and write
/// `action_dim` action entries.
///
/// # Errors
/// [`ImportError::Layout`] naming the file when it cannot be read, does not parse (with
/// the field), or its ranges do not fit the networks' widths or are not finite
/// `(min, max)` pairs with `max > min`.
pub fn read_statistics(path: &Path, proprio: usize, action_dim: usize) -> Result<Normalisation, ImportError> {
    let bad = |what: String| ImportError::Layout { path: path.to_path_buf(), what };
    let text = std::fs::read_to_string(path).map_err(|e| bad(format!("cannot be read: {e}")))?;
    let mut de = serde_json::Deserializer::from_str(&text);
    let n: Normalisation = serde_path_to_error::deserialize(&mut de).map_err(|e| {
        bad(format!(
            "not {{\"agent_pos\": {{\"min\", \"max\"}}, \"action\": {{..}}}} ({}: {})",
            e.path(),
            e.inner()
        ))
    })?;
    let (pw, aw) = (proprio, action_dim);
    let widths_agree = [&n.agent_pos, &n.action].iter().all(|r| r.min.len() == r.max.len())
        && n.agent_pos.dim() == pw
        && n.action.dim() == aw;
    let finite = [&n.agent_pos, &n.action]
        .iter()
        .all(|r| r.min.iter().zip(&r.max).all(|(lo, hi)| lo.is_finite() && hi.is_finite() && hi > lo));
    if !widths_agree || !finite {
        return Err(bad(format!(
            "agent_pos needs {pw} and action {aw} finite (min, max) pairs with max > min, for this checkpoint's networks"
        )));
    }
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_statistics_file_is_read_and_checked_against_the_widths() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("stats.json");
        let good =
            r#"{"agent_pos": {"min": [0, 0], "max": [1, 2]}, "action": {"min": [0, 0], "max": [3, 4]}}"#;
        std::fs::write(&path, good).unwrap();
        let n = read_statistics(&path, 2, 2).unwrap();
        assert_eq!((n.agent_pos.max.clone(), n.action.max.clone()), (vec![1.0, 2.0], vec![3.0, 4.0]));
        let err = read_statistics(&path, 2, 3).unwrap_err().to_string();
        assert!(err.contains("stats.json") && err.contains("action 3 finite"), "{err}");
        // max = min is no range.
        std::fs::write(&path, good.replace("[3, 4]", "[0, 4]")).unwrap();
        let err = read_statistics(&path, 2, 2).unwrap_err().to_string();
        assert!(err.contains("max > min"), "{err}");
        std::fs::write(&path, good.replace("\"max\": [1, 2]", "\"max\": \"high\"")).unwrap();
        let err = read_statistics(&path, 2, 2).unwrap_err().to_string();
        assert!(err.contains("agent_pos.max: invalid type"), "{err}");
        let err = read_statistics(&dir.path().join("none.json"), 2, 2).unwrap_err().to_string();
        assert!(err.contains("none.json: cannot be read"), "{err}");
    }
}
