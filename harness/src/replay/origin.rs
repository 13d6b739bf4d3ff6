//! Which task a dataset was collected in, read from its attributes as a typed view.
//!
//! evalharness writes `evalharness.scenario` into every dataset it makes. A dataset
//! without evalharness attributes at all is another codebase's Push-T replay buffer
//! (diffusion_policy's `pusht_cchi_v7_replay.zarr`, GPC's data), which is Push-T's by
//! construction. Anything else (attributes that do not parse, evalharness attributes
//! that name no task) is refused, never read as Push-T.

use std::path::Path;

use serde_json::Value;

use super::ReplayError;
use super::attrs::DatasetAttrs;
pub use super::attrs::EpisodeEntry;
use super::reader::group_paths;
use crate::zarr::read_attrs;

/// The task of datasets without evalharness attributes.
pub const FOREIGN_TASK: &str = "pusht";

/// The task named in root attributes `attrs` of the dataset group `path`.
///
/// # Errors
/// [`ReplayError::Layout`] naming `path` when the `evalharness` attributes cannot be read
/// or name no scenario.
pub fn scenario_in(path: &Path, attrs: &Value) -> Result<String, ReplayError> {
    match DatasetAttrs::from_root(path, attrs)? {
        None => Ok(FOREIGN_TASK.to_string()),
        Some(a) => a.scenario.ok_or_else(|| ReplayError::Layout {
            path: path.to_path_buf(),
            reason: "its evalharness attributes name no task (\"scenario\")".into(),
        }),
    }
}

/// The per-episode entries of a dataset's root attributes `attrs`: none for a dataset
/// without evalharness attributes or without the list.
///
/// # Errors
/// [`ReplayError::Layout`] naming `path` when the attributes (the list among them) cannot be
/// read (never read as absent).
pub fn episodes_in(path: &Path, attrs: &Value) -> Result<Vec<EpisodeEntry>, ReplayError> {
    Ok(DatasetAttrs::from_root(path, attrs)?.map(|a| a.episodes).unwrap_or_default())
}

/// The task a dataset (a group, or a folder of groups: its first) was collected in.
///
/// # Errors
/// Not a dataset, attributes that do not parse, or evalharness attributes that name
/// no task, naming the group.
pub fn scenario_of(path: &Path) -> Result<String, ReplayError> {
    let first = group_paths(path)?.swap_remove(0);
    let attrs = read_attrs(&first)?;
    scenario_in(&first, &attrs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn the_task_is_named_or_foreign_and_never_guessed() {
        let p = Path::new("d.zarr");
        assert_eq!(scenario_in(p, &json!({"evalharness": {"scenario": "lift", "seed": 1}})).unwrap(), "lift");
        assert_eq!(scenario_in(p, &json!({})).unwrap(), "pusht");
        let err = scenario_in(p, &json!({"evalharness": {"seed": 1}})).unwrap_err().to_string();
        assert!(err.contains("d.zarr") && err.contains("name no task"), "{err}");
        let err = scenario_in(p, &json!({"evalharness": {"scenario": 3}})).unwrap_err().to_string();
        assert!(err.contains("invalid type"), "{err}");
    }

    #[test]
    fn episode_entries_are_read_or_refused_never_guessed() {
        let p = Path::new("d.zarr");
        let attrs = json!({"evalharness": {"scenario": "lift", "episodes": [
            {"behaviour": "expert", "seed": 7, "steps": 51, "success": true}, {"seed": 8}]}});
        let e = episodes_in(p, &attrs).unwrap();
        let expert = EpisodeEntry {
            behaviour: Some("expert".into()),
            seed: Some(7),
            steps: Some(51),
            success: Some(true),
            ..EpisodeEntry::default()
        };
        assert_eq!(e[0], expert);
        assert_eq!(e[1], EpisodeEntry { seed: Some(8), ..EpisodeEntry::default() });
        // No list, or no evalharness attributes: none.
        assert!(episodes_in(p, &json!({"evalharness": {"scenario": "lift"}})).unwrap().is_empty());
        assert!(episodes_in(p, &json!({})).unwrap().is_empty());
        // A list that is not one of entries is refused, naming the dataset.
        let err = episodes_in(p, &json!({"evalharness": {"episodes": [{"behaviour": 3}]}})).unwrap_err();
        assert!(err.to_string().contains("d.zarr") && err.to_string().contains("behaviour"), "{err}");
    }

    #[test]
    fn a_folder_of_groups_is_read_from_its_first_group() {
        let dir = tempfile::tempdir().unwrap();
        for (name, task) in [("b.zarr", "can"), ("a.zarr", "lift")] {
            let g = dir.path().join(name);
            std::fs::create_dir_all(&g).unwrap();
            std::fs::write(g.join(".zgroup"), r#"{"zarr_format": 2}"#).unwrap();
            let attrs = json!({"evalharness": {"scenario": task}});
            std::fs::write(g.join(".zattrs"), attrs.to_string()).unwrap();
        }
        assert_eq!(scenario_of(dir.path()).unwrap(), "lift");
        assert_eq!(scenario_of(&dir.path().join("b.zarr")).unwrap(), "can");
        assert!(scenario_of(&dir.path().join("none")).is_err());
    }
}
