//! Loading a checkpoint of any policy kind: the learned kinds by `policy.json`'s `kind`
//! ([`load_policy`]; the folder format is [`crate::dir`]'s), and a task's `scripted` ones.
//!
//! The learned kinds live here (burn) and the `scripted` kind belongs to the task (its
//! expert plans with the task's simulator, `Task::scripted_policy`); this crate does not
//! know the tasks, so it dispatches on `policy.json`'s `kind` and hands a `scripted` folder
//! to the task it is given.

use std::path::Path;

use burn::tensor::Device;
use harness::policy::Policy;
use harness::task::Task;

use crate::diffusion::DiffusionPolicy;
use crate::dir::{
    Expectations, PolicyLoadError, checkpoint_name, diffusion_config, diffusion_weights, read_policy_file,
};

/// Loads the checkpoint folder `dir` for `task`.
///
/// # Errors
/// [`PolicyLoadError`] naming the folder (see [`load_policy`]; for `scripted`, an
/// unreadable `policy.json`, a bad config, or a task without scripted policies).
pub fn load_any(
    dir: &Path,
    expect: &Expectations,
    device: &Device,
    task: &dyn Task,
) -> Result<Box<dyn Policy>, PolicyLoadError> {
    if crate::dir::policy_kind(dir).as_deref() == Some("scripted") {
        return task.scripted_policy(dir).map_err(|e| PolicyLoadError::new(dir, e.to_string()));
    }
    load_policy(dir, expect, device)
}

/// What a learned checkpoint must match to run on `task`: its frame size, its
/// proprioception and its actions' width and bounds.
pub fn expectations(task: &dyn Task) -> Expectations {
    let (obs, act) = (task.observation_spec(), task.action_spec());
    Expectations {
        image_size: obs.image_size,
        proprio_dim: obs.proprio.len(),
        action_low: act.low,
        action_high: act.high,
        task: Some(task.name().to_string()),
        robot: obs.robot,
    }
}

/// Loads one checkpoint folder.
///
/// # Errors
/// [`PolicyLoadError`] naming the folder for a missing or invalid `policy.json`, an
/// unknown kind, a config that does not fit the scenario, or weights that are
/// missing, truncated or do not match the config.
pub fn load_policy(
    dir: &Path,
    expect: &Expectations,
    device: &Device,
) -> Result<Box<dyn Policy>, PolicyLoadError> {
    let err = |m: String| PolicyLoadError::new(dir, m);
    let file = read_policy_file(dir)?;
    let name = checkpoint_name(dir);
    if let (Some(theirs), Some(ours)) = (&file.task, &expect.task)
        && theirs != ours
    {
        return Err(err(format!("was trained on task {theirs}'s demonstrations; this run is task {ours}")));
    }
    match file.kind.as_str() {
        "diffusion" => {
            let cfg = diffusion_config(dir, &file)?;
            if cfg.net.image_size != expect.image_size {
                return Err(err(format!(
                    "takes {0}x{0} frames, the scenario renders {1}x{1}",
                    cfg.net.image_size, expect.image_size
                )));
            }
            if cfg.net.action_dim != expect.action_dim() {
                return Err(err(format!(
                    "outputs {}-D actions, the scenario takes {}-D",
                    cfg.net.action_dim,
                    expect.action_dim()
                )));
            }
            if cfg.net.proprio() != expect.proprio_dim {
                return Err(err(format!(
                    "reads {} proprioceptive entries, the scenario gives {}",
                    cfg.net.proprio(),
                    expect.proprio_dim
                )));
            }
            let (n, a) = (&file.normalisation, cfg.net.action_dim);
            let lengths_agree =
                n.agent_pos.max.len() == n.agent_pos.dim() && n.action.max.len() == n.action.dim();
            if !lengths_agree || n.agent_pos.dim() != cfg.net.proprio() || n.action.dim() != a {
                return Err(err(format!(
                    "policy.json \"normalisation\": {} proprioceptive and {} action entries, the config says {} and {a}",
                    n.agent_pos.dim(),
                    n.action.dim(),
                    cfg.net.proprio()
                )));
            }
            let net = diffusion_weights(dir, &cfg, device)?;
            let bounds = (expect.action_low.clone(), expect.action_high.clone());
            Ok(Box::new(DiffusionPolicy::new(name, cfg, file.normalisation, bounds, net, device)))
        }
        "gpc-diffusion" | "lerobot-diffusion" | "robomimic-diffusion" => {
            crate::imported_policy::load(dir, file, expect, device)
        }
        other => Err(err(format!(
            "unknown policy kind \"{other}\" (known: diffusion, gpc-diffusion, lerobot-diffusion, robomimic-diffusion, scripted)"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diffusion::{DiffusionConfig, Normalisation};
    use crate::dir::{PolicyFile, checkpoint_dirs};
    use crate::provenance::PolicyProvenance;

    #[test]
    fn errors_name_the_checkpoint() {
        let tmp = std::env::temp_dir().join(format!("evalharness-policy-{}", std::process::id()));
        let ck = tmp.join("epoch-0001");
        std::fs::create_dir_all(&ck).unwrap();
        let expect = &Expectations::pusht(96);
        let device = Device::flex();
        let e = load_policy(&ck, expect, &device).err().unwrap();
        assert!(e.to_string().contains("epoch-0001") && e.to_string().contains("policy.json"), "{e}");
        let norm = crate::diffusion::Range { min: vec![0.0; 2], max: vec![1.0; 2] };
        let mut file = PolicyFile::diffusion(
            &DiffusionConfig::default(),
            &Normalisation { agent_pos: norm.clone(), action: norm },
            1,
            1,
            &PolicyProvenance::default(),
            0.0,
            Some("pusht"),
        );
        file.kind = "transformer".into();
        std::fs::write(ck.join("policy.json"), serde_json::to_string(&file).unwrap()).unwrap();
        let e = load_policy(&ck, expect, &device).err().unwrap();
        assert!(e.to_string().contains("unknown policy kind \"transformer\""), "{e}");
        file.kind = "diffusion".into();
        std::fs::write(ck.join("policy.json"), serde_json::to_string(&file).unwrap()).unwrap();
        let e = load_policy(&ck, &Expectations::pusht(64), &device).err().unwrap();
        assert!(e.to_string().contains("96x96"), "{e}");
        // At 92f9f2b a checkpoint of another task with the same widths (Lift's on Can)
        // loaded and ranked; its recorded task is now checked first.
        let can = Expectations { task: Some("can".into()), ..Expectations::pusht(96) };
        let e = load_policy(&ck, &can, &device).err().unwrap();
        assert!(
            e.to_string().contains("trained on task pusht's demonstrations; this run is task can"),
            "{e}"
        );
        // Weights missing, then truncated.
        let e = load_policy(&ck, expect, &device).err().unwrap();
        assert!(e.to_string().contains("model.bpk"), "{e}");
        std::fs::write(ck.join("model.bpk"), b"not a burnpack").unwrap();
        let e = load_policy(&ck, expect, &device).err().unwrap();
        assert!(e.to_string().contains("model.bpk"), "{e}");
        assert_eq!(checkpoint_dirs(&tmp).unwrap(), vec![ck.clone()]);
        std::fs::remove_dir_all(&tmp).unwrap();
    }
}
