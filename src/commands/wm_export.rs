//! `evalharness wm export`: a world-model folder to ship or share, made from a
//! training run: the EMA weights that `rank` and `wm eval` load, `config.json`
//! with its autoencoder path rewritten relative to the new folder, the training
//! log, sessions and provenance, which gains an `exported` entry (command,
//! commit, source folder; one per export, oldest first). The trained weights and
//! the optimizer state, needed only to resume training, stay in the run.
//!
//! `--autoencoder` swaps the decoder: the folder uses another autoencoder with the
//! same encoder (checked), e.g. a narrower decoder trained with `train autoencoder
//! --encoder-from`, recorded in the provenance's `autoencoder_replaced`.
//!
//! The source must load as a model and have a `provenance.json` that describes
//! its weights (the same step as its checkpoint; a trainer writes it when a
//! session ends), and so must the copy, checked before it is reported.

use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use harness::provenance::{AutoencoderReplaced, Exported, WorldModelOrigin};
use world_model::model::{FolderConfig, WorldModel};
use world_model::train_ae::load_autoencoder;

use super::git_commit;
use crate::cli::WmExportArgs;
use crate::output::{Staged, write_json};
use harness::sessions::stale_provenance;
use trainers::world_model::relative_to;

/// Copied when present; `ema.bpk` is required.
const FILES: [&str; 5] =
    ["ema.bpk", "state.json", "train_log.jsonl", "sessions.jsonl", "init_from_provenance.json"];

/// Refuses `other` unless it encodes exactly as `trained_on`, the autoencoder whose
/// latents the world model was trained on.
fn check_same_encoder(trained_on: &Path, other: &Path, device: &burn::tensor::Device) -> Result<()> {
    let (ours, _) =
        load_autoencoder(trained_on, device).with_context(|| format!("{}", trained_on.display()))?;
    let (theirs, _) =
        load_autoencoder(other, device).with_context(|| format!("--autoencoder {}", other.display()))?;
    if !theirs.encodes_like(&ours, device) {
        bail!(
            "--autoencoder {}: its encoder differs from {}, whose latents the world model was trained on \
             (a decoder for this model is trained with `train autoencoder --encoder-from {}`)",
            other.display(),
            trained_on.display(),
            trained_on.display()
        );
    }
    Ok(())
}

/// `evalharness wm export`.
pub fn run(a: &WmExportArgs) -> Result<ExitCode> {
    let device = nn::device::selected()?;
    let mut source =
        WorldModel::load(&a.from, &device).with_context(|| format!("--from {}", a.from.display()))?;
    if let Some(alpha) = a.alpha {
        // The check `rank --alpha` and `wm eval --alpha` make: an accentuated model, α >= 1.
        source
            .set_alpha(alpha)
            .map_err(|e| anyhow::anyhow!("--alpha {alpha}: {e} ({})", a.from.display()))?;
    }
    let prov_path = a.from.join("provenance.json");
    if !prov_path.is_file() {
        bail!(
            "--from {}: no provenance.json (a trainer writes it when a session ends; \
             `train world-model --out {0} --resume --max-minutes 0` writes it without training)",
            a.from.display()
        );
    }
    let mut provenance: WorldModelOrigin = harness::provenance::read(&prov_path)?;
    if let Some(why) = stale_provenance(&a.from, provenance.steps())? {
        bail!(
            "--from {why}; `train world-model --out {} --resume --max-minutes 0` records that session \
             and rewrites provenance.json without training",
            a.from.display()
        );
    }
    let mut config = FolderConfig::read(&a.from)?;
    if let Some(alpha) = a.alpha {
        config.model.alpha = Some(alpha);
    }
    let inputs = crate::output::Inputs::new()
        .world_model("--from", &a.from)
        .maybe("--autoencoder", a.autoencoder.as_deref());
    let staged = Staged::new(&a.out, a.force, &inputs)?;
    if let Some(ae) = config.model.autoencoder.clone() {
        let trained_on = a.from.join(ae);
        let target = match &a.autoencoder {
            Some(other) => {
                check_same_encoder(&trained_on, other, &device)?;
                other.clone()
            }
            None => trained_on.clone(),
        };
        // The staging folder is the output's sibling, so paths relative to it hold.
        let moved = relative_to(&staged.file(""), &target)?;
        if let WorldModelOrigin::Trained(p) = &mut provenance {
            if let Some(other) = &a.autoencoder {
                // Relative to the exported folder, as the config's path: the path as given
                // depends on the directory the command ran in (it is in "exported"'s command).
                p.autoencoder_replaced = Some(AutoencoderReplaced {
                    now: moved.display().to_string(),
                    now_provenance: harness::provenance::snapshot(other),
                    trained_on: trained_on.display().to_string(),
                });
            }
            p.autoencoder = Some(moved.display().to_string());
        }
        config.model.autoencoder = Some(moved);
    } else if let Some(other) = &a.autoencoder {
        bail!(
            "--autoencoder {}: {} is a pixel-space model (no autoencoder)",
            other.display(),
            a.from.display()
        );
    }
    write_json(&staged.file("config.json"), &config)?;
    for name in FILES {
        let (src, dst) = (a.from.join(name), staged.file(name));
        if src.is_file() {
            std::fs::copy(&src, &dst).with_context(|| format!("copying {}", src.display()))?;
        }
    }
    let command: Vec<String> = crate::stdout::command_line();
    provenance.exported_mut().push(Exported {
        alpha: a.alpha,
        changed: None,
        command: command.join(" "),
        commit: git_commit(),
        from: a.from.display().to_string(),
        other: Default::default(),
    });
    write_json(&staged.file("provenance.json"), &provenance)?;
    let out = staged.commit()?;
    WorldModel::load(&out, &device)
        .with_context(|| format!("{}: the exported model does not load", out.display()))?;
    outln!("{}", out.display());
    Ok(ExitCode::SUCCESS)
}
