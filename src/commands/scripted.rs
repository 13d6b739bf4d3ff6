//! `evalharness scripted`: writes scripted-policy checkpoints — the Push-T expert
//! acting from frames with a given action noise and lag — one per combination,
//! so a graded policy set exists without any training.

use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use scenarios::pusht::scripted::{ScriptedConfig, ScriptedFile};
use serde_json::json;

use super::git_commit;
use crate::cli::ScriptedArgs;
use crate::output::{Staged, write_json};

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
    let combos: Vec<(String, f64, usize)> =
        a.noise.iter().flat_map(|&n| a.lag.iter().map(move |&l| (folder(n, l), n, l))).collect();
    for (i, (name, noise, _)) in combos.iter().enumerate() {
        if combos[..i].iter().any(|c| &c.0 == name) {
            bail!("--noise {noise} rounds to a folder that already exists ({name})");
        }
    }
    let out = Staged::new(&a.out, a.force, &crate::output::Inputs::new())?;
    let command: Vec<String> = crate::stdout::command_line();
    let provenance = json!({"command": command.join(" "), "commit": git_commit()});
    for (name, noise, lag) in &combos {
        let file = ScriptedFile {
            kind: "scripted".into(),
            config: ScriptedConfig { noise: *noise, lag: *lag, action_horizon: a.action_horizon },
            provenance: provenance.clone(),
        };
        let dir = out.file(name);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        write_json(&dir.join("policy.json"), &serde_json::to_value(&file)?)?;
    }
    let root = out.commit()?;
    for (name, _, _) in &combos {
        outln!("{}", root.join(name).display());
    }
    Ok(ExitCode::SUCCESS)
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
