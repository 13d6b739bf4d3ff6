//! `evalharness train ...`: model training commands.
//!
//! Each run writes into its `--out` folder as it goes (checkpoints every few
//! steps), can be time-boxed with `--max-minutes` and continued with `--resume`,
//! and ends with `provenance.json` (command, seed, commit, data, steps, metrics).

use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use serde_json::json;
use world_model::autoencoder::AutoencoderConfig;
use world_model::data::EpisodeData;
use world_model::train_ae::{AeTrainConfig, RunOptions, train_autoencoder};

use crate::cli::TrainAutoencoderArgs;
use crate::output::write_json;
use crate::progress;

/// The commit of the working tree, or "unknown" outside a git checkout.
fn git_commit() -> String {
    let out = std::process::Command::new("git").args(["rev-parse", "HEAD"]).output();
    let dirty =
        std::process::Command::new("git").args(["status", "--porcelain", "--untracked-files=no"]).output();
    match out {
        Ok(o) if o.status.success() => {
            let mut c = String::from_utf8_lossy(&o.stdout).trim().to_string();
            if dirty.is_ok_and(|d| !d.stdout.is_empty()) {
                c.push_str("+dirty");
            }
            c
        }
        _ => "unknown".into(),
    }
}

/// `evalharness train autoencoder`.
pub fn autoencoder(a: &TrainAutoencoderArgs, quiet: bool) -> Result<ExitCode> {
    if a.out.exists() && !a.resume {
        if !a.force {
            bail!(
                "{} already exists (pass --resume to continue it or --force to replace it)",
                a.out.display()
            );
        }
        std::fs::remove_dir_all(&a.out).with_context(|| format!("removing {}", a.out.display()))?;
    }
    if a.resume && !a.out.join("state.json").is_file() {
        bail!("--resume: {} has no checkpoint (state.json)", a.out.display());
    }
    let model_cfg = AutoencoderConfig::new();
    let cfg = AeTrainConfig {
        steps: a.steps.unwrap_or(4000),
        batch: a.batch,
        lr: a.lr,
        seed: a.seed,
        eval_every: a.eval_every.max(1),
        checkpoint_every: a.checkpoint_every.max(1),
        ..AeTrainConfig::default()
    };
    tracing::info!(data = %a.data.display(), "loading frames");
    let data = EpisodeData::load(&a.data, model_cfg.image_size)?;
    tracing::info!(frames = data.len(), episodes = data.episodes.len(), "loaded");
    let pb = progress::bar(cfg.steps, "autoencoder", quiet);
    let run = RunOptions { resume: a.resume, extend: a.steps.is_some(), max_minutes: a.max_minutes };
    let outcome = train_autoencoder(&data, &a.out, &model_cfg, &cfg, run, &mut |p| {
        pb.set_position(p.step);
        match p.psnr {
            Some(v) => pb.set_message(format!("loss {:.5} psnr {v:.2}", p.loss)),
            None => pb.set_message(format!("loss {:.5}", p.loss)),
        }
    })?;
    pb.finish_and_clear();
    // Filmstrip: held-out frames (top) over their reconstructions (bottom).
    let size = model_cfg.image_size;
    let (top, bottom): (Vec<Vec<u8>>, Vec<Vec<u8>>) = outcome.samples.iter().cloned().unzip();
    let strip = reports::png::filmstrip(&[top, bottom], size, size);
    let strip_path = a.out.join("reconstructions.png");
    reports::png::write_png(&strip_path, &strip.pixels, strip.width, strip.height)?;
    let args: Vec<String> = std::env::args().collect();
    write_json(
        &a.out.join("provenance.json"),
        &json!({
            "what": "frame autoencoder (96x96x3 <-> 12x12x8)",
            "command": args.join(" "),
            "seed": a.seed,
            "commit": git_commit(),
            "data": {
                "path": a.data.display().to_string(),
                "episodes": data.episodes.len(),
                "frames": data.len(),
                "held_out": "episodes with index % 10 == 9",
            },
            "steps": outcome.step,
            "finished": outcome.finished,
            "elapsed_s": outcome.elapsed_s,
            "metrics": {"held_out_psnr_db": outcome.psnr, "held_out_mse": outcome.mse},
        }),
    )?;
    println!(
        "autoencoder: step {}/{}{}, held-out PSNR {:.2} dB, MSE {:.6} -> {}",
        outcome.step,
        outcome.total,
        if outcome.finished { "" } else { " (stopped early; --resume continues)" },
        outcome.psnr,
        outcome.mse,
        a.out.display()
    );
    Ok(ExitCode::SUCCESS)
}
