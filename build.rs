//! Bakes the MuJoCo library folder (set by .cargo/config.toml, filled by
//! scripts/setup.sh) into the rpath of the evalharness binary and its tests, and
//! records the commit the binary is built from (`EVALHARNESS_BUILD_COMMIT`, with
//! `+dirty` when tracked files differ from it) for the provenance files it writes:
//! asking git when a training run ends would name whatever is checked out then.

use std::process::Command;

fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if let Ok(dir) = std::env::var("MUJOCO_DYNAMIC_LINK_DIR") {
        println!("cargo::rustc-link-arg=-Wl,-rpath,{dir}");
    }
    // A new commit moves HEAD or its ref; an edit touches the sources.
    for watched in [".git/HEAD", ".git/refs", ".git/packed-refs", "Cargo.toml", "Cargo.lock", "build.rs"] {
        println!("cargo::rerun-if-changed={watched}");
    }
    for dir in
        ["src", "harness", "engine", "world_model", "policies", "scenarios", "reports", "benches", "tests"]
    {
        println!("cargo::rerun-if-changed={dir}");
    }
    println!("cargo::rustc-env=EVALHARNESS_BUILD_COMMIT={}", build_commit());
}

/// `git rev-parse HEAD`, `+dirty` if tracked files differ from it, or "unknown".
fn build_commit() -> String {
    let git = |args: &[&str]| Command::new("git").args(args).output().ok().filter(|o| o.status.success());
    let Some(head) = git(&["rev-parse", "HEAD"]) else {
        return "unknown".into();
    };
    let mut commit = String::from_utf8_lossy(&head.stdout).trim().to_string();
    if git(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|o| !o.stdout.is_empty()) {
        commit.push_str("+dirty");
    }
    commit
}
