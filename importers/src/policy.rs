//! `evalharness import policy`: another codebase's policy checkpoint as an evalharness
//! checkpoint folder. A DriftWorld/GPC Push-T diffusion policy becomes a `"gpc-diffusion"`
//! checkpoint (sizes read from the file, GPC's sampling, the normalisation statistics GPC's
//! evaluation script uses), a LeRobot diffusion policy a `"lerobot-diffusion"` one (settings
//! from its `config.json`, statistics from its files), a robomimic one a `"robomimic-diffusion"`
//! one ([`super::import_robomimic`]): `policy.json` (with the sources'
//! SHA-256, the command, the commit) and `model.bpk` (f32, as trained). The folder is staged,
//! replaces `--out` only once complete, and must load before the command reports it.

use crate::error::{Context, Result, refuse};
use crate::{Invocation, say};
use policies::dir::{Expectations, PolicyFile, write_policy_f32};
use policies::import_gpc::{GpcWeights, import};
use policies::kinds::load_policy;
use policies::provenance::PolicyProvenance;
use serde_json::json;

use crate::args::{ImportPolicyArgs, PolicyFormat, PolicyWeights};
use runner::output::{Inputs, Staged};

/// `evalharness import policy`.
pub fn run(a: &ImportPolicyArgs, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<()> {
    if a.stats.is_some() && a.format != PolicyFormat::Gpc {
        refuse!(
            "--stats is read with --format gpc only: LeRobot's and robomimic's files carry their statistics"
        );
    }
    if a.scenario.is_some() && a.format != PolicyFormat::Robomimic {
        refuse!(
            "--scenario is read with --format robomimic only (GPC's policies are Push-T's; LeRobot's folders are checked when ranked)"
        );
    }
    match a.format {
        PolicyFormat::Gpc => gpc(a, inv, say),
        PolicyFormat::Lerobot => lerobot(a, inv, say),
        PolicyFormat::Robomimic => crate::robomimic::run(a, inv, say),
    }
}

/// A LeRobot `pretrained_model` folder.
fn lerobot(a: &ImportPolicyArgs, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<()> {
    if !a.file.join("config.json").is_file() {
        refuse!(
            "{}: --format lerobot reads a pretrained_model folder (config.json, model.safetensors); this has no config.json",
            a.file.display()
        );
    }
    if a.weights == PolicyWeights::Model {
        refuse!("--weights model: a LeRobot folder holds one copy of the weights (leave --weights out)");
    }
    let staged = Staged::new(&a.out, a.force, &Inputs::new().add("FILE", &a.file))?;
    let sha = |name: &str| {
        let p = a.file.join(name);
        harness::fingerprint::file(&p).with_context(|| format!("{}", p.display()))
    };
    let (cfg_sha, model_sha) = (sha("config.json")?, sha("model.safetensors")?);
    let device = nn::device::selected()?;
    let p = policies::import_lerobot::import(&a.file, &device)?;
    let stats_sha = harness::fingerprint::file(&p.stats_from)?;
    let file = PolicyFile {
        kind: "lerobot-diffusion".into(),
        epoch: 0,
        step: 0,
        config: serde_json::to_value(&p.cfg)?,
        normalisation: p.norm.clone(),
        provenance: PolicyProvenance {
            import: Some(json!({
                "format": "lerobot",
                "source": a.file.display().to_string(),
                "config_sha256": cfg_sha,
                "model_sha256": model_sha,
                "statistics": {"source": p.stats_from.display().to_string(), "sha256": stats_sha},
                "tensors": p.tensors,
                "epoch_and_step": "not in a LeRobot folder: 0",
            })),
            ..PolicyProvenance::new(inv.command_line.clone().join(" "), inv.commit.clone())
        },
        train_loss: None,
        task: None,
    };
    write_policy_f32(staged.dir(), &file, &p.net)?;
    let out = staged.commit()?;
    let n = &p.cfg.net;
    let expect = Expectations {
        image_size: n.image_size,
        proprio_dim: n.proprio(),
        action_low: p.norm.action.min.clone(),
        action_high: p.norm.action.max.clone(),
        task: None,
        robot: Vec::new(),
    };
    load_policy(&out, &expect, &device)
        .with_context(|| format!("{}: the imported policy does not load", out.display()))?;
    say!(say, "{}", out.display());
    Ok(())
}

/// A GPC checkpoint file.
fn gpc(a: &ImportPolicyArgs, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<()> {
    let staged = Staged::new(&a.out, a.force, &Inputs::new().add("FILE", &a.file))?;
    // A checkpoint file, or GPC's "official" folder of three files: each one's SHA-256.
    let files: Vec<std::path::PathBuf> = if a.file.is_dir() {
        policies::import_gpc::FOLDER_FILES.iter().map(|f| a.file.join(f)).collect()
    } else {
        vec![a.file.clone()]
    };
    let mut sha = serde_json::Map::new();
    for f in &files {
        if f.is_file() {
            let h = harness::fingerprint::file(f).with_context(|| format!("{}", f.display()))?;
            sha.insert(f.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(), h.into());
        }
    }
    let sha = if a.file.is_dir() {
        serde_json::Value::Object(sha)
    } else {
        sha.into_iter().next().map(|(_, v)| v).unwrap_or_default()
    };
    let device = nn::device::selected()?;
    let weights = match a.weights {
        PolicyWeights::Ema => GpcWeights::Ema,
        PolicyWeights::Model => GpcWeights::Model,
    };
    let p = import(&a.file, weights, usize::from(a.image_size), &device)?;
    let (normalisation, stats) = match &a.stats {
        None => (
            policies::gpc_stats::pusht_normalisation(),
            json!(
                "GPC's Push-T evaluation script's agent-position and action ranges (not stored in the checkpoint)"
            ),
        ),
        Some(f) => {
            let n = policies::gpc_stats::read_statistics(f, p.cfg.net.proprio(), p.cfg.net.action_dim)
                .with_context(|| format!("--stats {}", f.display()))?;
            let sha = harness::fingerprint::file(f).with_context(|| format!("{}", f.display()))?;
            (n, json!({"source": f.display().to_string(), "sha256": sha}))
        }
    };
    let file = PolicyFile {
        kind: "gpc-diffusion".into(),
        epoch: epoch_of(&a.file).unwrap_or(0),
        step: p.step.and_then(|s| u64::try_from(s).ok()).unwrap_or(0),
        config: serde_json::to_value(&p.cfg)?,
        normalisation,
        provenance: PolicyProvenance {
            import: Some(json!({
                "format": "gpc",
                "source": a.file.display().to_string(),
                "sha256": sha,
                "step": p.step,
                "epoch": if epoch_of(&a.file).is_some() { "from the file name" } else { "unknown (the file name has no ep<N>): 0" },
                "layout": if a.file.is_dir() { "GPC's folder (vision_encoder.pth, invariant.pth, ema_nets.pth)" } else { "a checkpoint file" },
                "weights": match a.weights { PolicyWeights::Ema => "ema.shadow_params", PolicyWeights::Model => "model" },
                "tensors": p.tensors,
                "normalisation": stats,
                "sampling": "DDPM, every one of the 100 training steps, squared-cosine betas, x0 clipped",
            })),
            ..PolicyProvenance::new(inv.command_line.clone().join(" "), inv.commit.clone())
        },
        train_loss: None,
        task: Some("pusht".into()),
    };
    write_policy_f32(staged.dir(), &file, &p.net)?;
    let out = staged.commit()?;
    load_policy(&out, &Expectations::pusht(usize::from(a.image_size)), &device)
        .with_context(|| format!("{}: the imported policy does not load", out.display()))?;
    say!(say, "{}", out.display());
    Ok(())
}

/// The epoch in a GPC checkpoint's name (`ckpt-ep50.pth` → 50).
fn epoch_of(path: &std::path::Path) -> Option<u64> {
    let stem = path.file_stem()?.to_str()?;
    stem.rsplit_once("ep")?.1.parse().ok()
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_epoch_is_read_from_gpcs_file_names() {
        assert_eq!(super::epoch_of(std::path::Path::new("dir/ckpt-ep650.pth")), Some(650));
        assert_eq!(super::epoch_of(std::path::Path::new("policy.pth")), None);
    }
}
