//! `evalharness train policy`: trains a diffusion policy on the dataset's expert
//! demonstrations and saves a checkpoint every `--save-every` epochs.

use std::process::ExitCode;

use anyhow::{Result, bail};
use policies::data::Demos;
use policies::diffusion::DiffusionConfig;
use policies::net::NetConfig;
use policies::train::{PolicyRun, PolicyTrainConfig, RunConfigs, train_policy};
use serde_json::json;

use super::train::{dataset_origin, git_commit, prepare_out};
use crate::cli::TrainPolicyArgs;
use crate::progress;

/// `evalharness train policy`.
pub fn run(a: &TrainPolicyArgs, quiet: bool) -> Result<ExitCode> {
    prepare_out(&a.out, a.resume, a.force, ".train/state.json")?;
    if a.batch == 0 || a.epochs == Some(0) || a.save_every == 0 {
        bail!("--batch, --epochs and --save-every must be positive");
    }
    let policy = DiffusionConfig {
        net: NetConfig::new().with_encoder_width(a.encoder_width).with_down_dims(a.down_dims.clone()),
        inference_steps: a.inference_steps,
        ..DiffusionConfig::default()
    };
    let behaviour = (a.behaviour != "all").then_some(a.behaviour.as_str());
    tracing::info!(data = %a.data.display(), ?behaviour, "loading demonstrations");
    let demos = Demos::load(&a.data, behaviour, a.episodes, policy.net.image_size)?;
    tracing::info!(episodes = demos.episodes.len(), samples = demos.len(), "loaded");
    let args: Vec<String> = std::env::args().collect();
    let configs = RunConfigs {
        train: PolicyTrainConfig {
            epochs: a.epochs.unwrap_or(20),
            save_every: a.save_every,
            batch: a.batch,
            lr: a.lr,
            warmup: 200,
            weight_decay: 1e-6,
            seed: a.seed,
            checkpoint_every: 50,
        },
        normalisation: demos.normalisation(),
        provenance: json!({
            "command": args.join(" "),
            "commit": git_commit(),
            "seed": a.seed,
            "data": {
                "path": a.data.display().to_string(),
                "behaviour": a.behaviour,
                "episodes": demos.episodes.len(),
                "samples": demos.len(),
                "collected_with": dataset_origin(&a.data),
            },
        }),
        policy,
    };
    let pb = progress::bar(1, "policy", quiet);
    let run = PolicyRun { resume: a.resume, epochs: a.epochs, max_minutes: a.max_minutes };
    let outcome = train_policy(&demos, &a.out, &configs, run, &mut |p| {
        pb.set_length(p.total);
        pb.set_position(p.step);
        pb.set_message(format!("epoch {} loss {:.4}", p.epoch, p.loss));
    })?;
    pb.finish_and_clear();
    for ck in &outcome.saved {
        println!("saved {}", ck.display());
    }
    println!(
        "policy: step {}/{}{}, mean loss (last 50 steps) {:.4} -> {}",
        outcome.step,
        outcome.total,
        if outcome.step >= outcome.total { "" } else { " (stopped early; --resume continues)" },
        outcome.loss,
        a.out.display()
    );
    Ok(ExitCode::SUCCESS)
}
