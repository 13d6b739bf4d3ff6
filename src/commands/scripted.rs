//! `evalharness scripted`: writes scripted-policy checkpoints — the Push-T expert
//! acting from frames with a given action noise and lag — one per combination,
//! so a graded policy set exists without any training.

use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use scenarios::pusht::scripted::{ScriptedConfig, ScriptedFile};
use serde_json::json;

use super::train::git_commit;
use crate::cli::ScriptedArgs;

/// The checkpoint folder name of a combination: `noise030-lag2`.
fn folder(noise: f64, lag: usize) -> String {
    format!("noise{:03}-lag{lag}", noise.round() as u64)
}

/// `evalharness scripted`.
pub fn run(a: &ScriptedArgs) -> Result<ExitCode> {
    if a.noise.iter().any(|n| !(n.is_finite() && *n >= 0.0)) {
        bail!("--noise values must be finite and >= 0");
    }
    if a.action_horizon == 0 || a.lag.iter().any(|&l| l >= a.action_horizon) {
        bail!("--lag values must be below --action-horizon ({}), which must be positive", a.action_horizon);
    }
    if a.out.exists() && !a.force {
        bail!("{} exists; pass --force to replace it", a.out.display());
    }
    if a.force && a.out.exists() {
        std::fs::remove_dir_all(&a.out).with_context(|| format!("removing {}", a.out.display()))?;
    }
    let command: Vec<String> = std::env::args().collect();
    let mut names = Vec::new();
    for &noise in &a.noise {
        for &lag in &a.lag {
            let name = folder(noise, lag);
            if names.contains(&name) {
                bail!("--noise {noise} rounds to a folder that already exists ({name})");
            }
            let file = ScriptedFile {
                kind: "scripted".into(),
                config: ScriptedConfig { noise, lag, action_horizon: a.action_horizon },
                provenance: json!({"command": command.join(" "), "commit": git_commit()}),
            };
            write(&a.out.join(&name), &file)?;
            println!("{}", a.out.join(&name).display());
            names.push(name);
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn write(dir: &Path, file: &ScriptedFile) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join("policy.json");
    let text = serde_json::to_string_pretty(file)? + "\n";
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folders_sort_by_noise_then_lag() {
        assert_eq!(folder(0.0, 0), "noise000-lag0");
        assert_eq!(folder(30.4, 2), "noise030-lag2");
        assert!(folder(5.0, 0) < folder(40.0, 0) && folder(40.0, 0) < folder(100.0, 0));
    }
}
