//! `evalharness import policy --format robomimic`: a robomimic diffusion-policy checkpoint as a
//! `"robomimic-diffusion"` checkpoint folder for Lift or Can. The policy's robot-state keys are
//! matched to what the scenario gives before anything is written; the folder (`policy.json` with
//! the source's SHA-256, the settings read and the command; `model.bpk`) is staged, must load for
//! the scenario, and only then replaces `--out`.

use crate::error::{Context, ImportCmdError, Result, refuse};
use crate::{Invocation, say};
use policies::dir::{PolicyFile, write_policy_f32};
use policies::import_robomimic::{RobomimicWeights, declared, import};
use policies::kinds::load_policy;
use policies::provenance::PolicyProvenance;
use serde_json::json;

use crate::args::{ImportPolicyArgs, PolicyWeights};
use policies::kinds::expectations;
use runner::output::{Inputs, Staged};

/// The evalharness scenario of a robomimic `env_name`.
fn scenario_of(env_name: &str) -> Option<&'static str> {
    match env_name {
        "Lift" => Some("lift"),
        "PickPlaceCan" => Some("can"),
        _ => None,
    }
}

/// `evalharness import policy --format robomimic`.
pub fn run(a: &ImportPolicyArgs, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<()> {
    if a.file.is_dir() {
        refuse!(
            "{}: --format robomimic reads a checkpoint file (model_epoch_N.pth), not a folder",
            a.file.display()
        );
    }
    let declared = declared(&a.file)?;
    let keys = declared.low_dim;
    let device = nn::device::selected()?;
    let weights = match a.weights {
        PolicyWeights::Ema => RobomimicWeights::Ema,
        PolicyWeights::Model => RobomimicWeights::Model,
    };
    let sha = harness::fingerprint::file(&a.file).with_context(|| format!("{}", a.file.display()))?;
    let spec = match &a.scenario {
        Some(s) => s.clone(),
        None => {
            let env = declared.env_name.unwrap_or_default();
            match scenario_of(&env) {
                Some(s) => s.to_string(),
                None => refuse!(
                    "{}: env_metadata.env_name is {env:?}, which is not Lift or PickPlaceCan; name the scenario with --scenario",
                    a.file.display()
                ),
            }
        }
    };
    let task = scenarios::load_task(&spec).with_context(|| format!("loading scenario {spec}"))?;
    let expect = expectations(task.as_ref());
    harness::task::robot_slices(&expect.robot, &keys).map_err(|m| {
        ImportCmdError::Refused(format!(
            "{}: the policy {m}; it cannot run on scenario {spec}",
            a.file.display()
        ))
    })?;
    let p = import(&a.file, weights, expect.image_size, &device)?;
    let staged = Staged::new(&a.out, a.force, &Inputs::new().add("FILE", &a.file))?;
    let file = PolicyFile {
        kind: "robomimic-diffusion".into(),
        epoch: p.epoch.and_then(|e| u64::try_from(e).ok()).unwrap_or(0),
        step: 0,
        config: serde_json::to_value(&p.cfg)?,
        normalisation: p.norm.clone(),
        provenance: PolicyProvenance {
            import: Some(json!({
                "format": "robomimic",
                "source": a.file.display().to_string(),
                "sha256": sha,
                "weights": p.weights,
                "epoch": p.epoch,
                "env_name": p.env_name,
                "tensors": p.tensors,
                "observation": {
                    "image": format!("{} (rendered at {1}x{1}, resized to the policy's {2}x{2})", policies::import_robomimic::IMAGE_KEY, expect.image_size, p.cfg.input_size.unwrap_or(expect.image_size)),
                    "robot_state": keys,
                    "robot_state_in_imagination": "estimated from the reset state and the commands since (the world model imagines frames only)",
                },
                "normalisation": "the checkpoint's action_normalization_stats and obs_normalization_stats (none stored: the identity)",
            })),
            ..PolicyProvenance::new(inv.command_line.clone().join(" "), inv.commit.clone())
        },
        train_loss: None,
        task: Some(task.name().to_string()),
    };
    write_policy_f32(staged.dir(), &file, &p.net)?;
    load_policy(staged.dir(), &expect, &device)
        .with_context(|| format!("{}: the imported policy does not load", a.out.display()))?;
    let out = staged.commit()?;
    say!(say, "{}", out.display());
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn robomimics_env_names_are_evalharness_scenarios() {
        assert_eq!(super::scenario_of("Lift"), Some("lift"));
        assert_eq!(super::scenario_of("PickPlaceCan"), Some("can"));
        assert_eq!(super::scenario_of("NutAssemblySquare"), None);
    }
}
