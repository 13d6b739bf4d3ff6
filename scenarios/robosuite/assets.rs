//! Where robosuite's scene assets live on this machine.
//!
//! `scripts/setup.sh` unpacks the files the Lift and Can scenes read from the
//! pinned `robosuite==1.5.2` wheel into `.robosuite/assets` (git-ignored). The
//! build bakes that folder's path in; `EVALHARNESS_ROBOSUITE_ASSETS` overrides it
//! (for a binary copied to another machine).

use std::path::{Path, PathBuf};

use crate::error::ScenarioError;

/// The robosuite release the assets come from.
pub const ROBOSUITE_VERSION: &str = "1.5.2";

/// The environment variable that overrides the asset folder.
pub const ASSETS_ENV: &str = "EVALHARNESS_ROBOSUITE_ASSETS";

/// The asset folder (robosuite's `models/assets`), checked to hold the files the
/// scenes read.
///
/// # Errors
/// [`ScenarioError::MissingAssets`] naming the folder and the first missing
/// file, telling the user to run `scripts/setup.sh`.
pub fn assets_dir() -> Result<PathBuf, ScenarioError> {
    let dir = match std::env::var_os(ASSETS_ENV) {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(env!("EVALHARNESS_ROBOSUITE_DEFAULT")),
    };
    check(&dir)?;
    Ok(dir)
}

/// The files every robosuite scene of evalharness reads, relative to the folder.
const REQUIRED: &[&str] = &[
    "robots/panda/robot.xml",
    "grippers/panda_gripper.xml",
    "bases/rethink_mount.xml",
    "arenas/table_arena.xml",
    "arenas/bins_arena.xml",
    "objects/can.xml",
    "objects/meshes/can.msh",
    "objects/meshes/milk.stl",
    "objects/meshes/bread.stl",
    "objects/meshes/cereal.stl",
    "textures/red-wood.png",
    "textures/soda.png",
];

fn check(dir: &Path) -> Result<(), ScenarioError> {
    for f in REQUIRED {
        if !dir.join(f).is_file() {
            return Err(ScenarioError::MissingAssets { dir: dir.to_path_buf(), missing: (*f).to_string() });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_empty_folder_names_the_missing_file_and_the_fix() {
        let dir = std::env::temp_dir().join("evalharness-no-robosuite-assets");
        std::fs::create_dir_all(&dir).unwrap();
        let e = check(&dir).unwrap_err();
        let text = e.to_string();
        assert!(text.contains("robots/panda/robot.xml"), "{text}");
        assert!(text.contains("scripts/setup.sh"), "{text}");
    }
}
