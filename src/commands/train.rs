//! `evalharness train ...`: model training commands.
//!
//! Each run writes into its `--out` folder as it goes (checkpoints every few
//! steps), can be time-boxed with `--max-minutes` and continued with `--resume`,
//! and ends with `provenance.json` (command, seed, commit, data, steps, metrics).

use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use harness::provenance::{AutoencoderMetrics, AutoencoderProvenance, FramesUsed, Source};
use harness::replay::attrs::{DatasetAttrs, Recipe};
use world_model::autoencoder::AutoencoderConfig;
use world_model::data::EpisodeData;
use world_model::train_ae::{AeConfigs, AeTrainConfig, RunOptions, read_configs, train_autoencoder};

use crate::cli::TrainAutoencoderArgs;
use crate::progress;
use harness::sessions::{open_session, read_step, record_session};

/// The task a dataset was collected in ([`harness::replay::origin`]: its attributes name
/// it; another codebase's Push-T replay buffer has none).
///
/// # Errors
/// A dataset whose attributes cannot be read or name no task, or a task this build
/// cannot load.
pub(super) fn dataset_task(data: &std::path::Path) -> Result<Box<dyn harness::task::Task>> {
    let scenario = harness::replay::origin::scenario_of(data)?;
    crate::scenario::load_task(&scenario).with_context(|| format!("{}: its task {scenario}", data.display()))
}

/// How an evalharness dataset was collected (from its attributes), to regenerate it:
/// `collect` is deterministic, so the same arguments give the same bytes. A merged
/// dataset lists the recipe of each of its inputs, in order. `None` for a dataset
/// evalharness did not make.
///
/// # Errors
/// A dataset whose attributes cannot be read (never taken for one without them).
pub(super) fn dataset_origin(data: &std::path::Path) -> Result<Option<Recipe>> {
    let attrs = harness::zarr::read_attrs(data)?;
    Ok(DatasetAttrs::from_root(data, &attrs)?.map(|a| a.recipe(None)))
}

/// Ctrl-C / SIGTERM during training: the first asks the trainer to stop after the
/// step in progress (it saves its checkpoint and provenance; `--resume` continues);
/// a second one exits at once with code 2.
pub(super) fn stop_on_signals() {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let flag = harness::stop::flag();
    for sig in [SIGINT, SIGTERM] {
        // The conditional shutdown runs first and exits only if the flag is already set.
        let registered = signal_hook::flag::register_conditional_shutdown(sig, 2, flag.clone())
            .and_then(|_| signal_hook::flag::register(sig, flag.clone()));
        if let Err(e) = registered {
            tracing::warn!(signal = sig, error = %e, "cannot catch the signal; an interrupt loses the steps since the last checkpoint");
        }
    }
}

/// A setting `--resume` cannot change: the flag's clap id, the value this command
/// line gives it and the run's saved value.
pub(super) type FixedFlag = (&'static str, serde_json::Value, serde_json::Value);

/// The flag `id`'s value on this command line and in the saved run, as JSON (how the
/// refusal shows the saved one).
pub(super) fn fixed<T: serde::Serialize>(id: &'static str, fresh: &T, saved: &T) -> FixedFlag {
    let json = |v: &T| serde_json::to_value(v).unwrap_or_default();
    (id, json(fresh), json(saved))
}

/// `--resume` continues a run with the settings saved in `saved` (its config file).
/// A flag typed on this `train <subcommand>` command line whose value differs from the
/// saved one would be silently ignored, so the run is refused, naming each such flag
/// with its saved value (flags left at their defaults are not compared).
pub(super) fn refuse_contradicting_flags(
    saved: &std::path::Path,
    subcommand: &str,
    fixed: &[FixedFlag],
) -> Result<()> {
    let given = crate::cli::given_on_command_line(&["train", subcommand]);
    let conflicts: Vec<String> = fixed
        .iter()
        .filter(|(id, ours, theirs)| given.iter().any(|g| g == id) && ours != theirs)
        .map(|(id, _, theirs)| format!("--{} (saved: {theirs})", id.replace('_', "-")))
        .collect();
    if conflicts.is_empty() {
        return Ok(());
    }
    bail!(
        "--resume continues the run with the settings saved in {}, which {} contradict: {}; \
         drop them, or start a new run",
        saved.display(),
        if conflicts.len() == 1 { "this flag would" } else { "these flags would" },
        conflicts.join(", ")
    )
}

/// Checks a training run's inputs and output folder, then prepares it: an existing
/// one needs `--resume` (and then its checkpoint, `state` relative to it) or `--force`
/// (which moves it aside until the new run completes, see
/// [`crate::output::RunDir`]). Each input (with its flag) must exist and lie apart
/// from the output.
pub(super) fn prepare_out(
    out: &std::path::Path,
    resume: bool,
    force: bool,
    state: &'static str,
    inputs: &[(&str, &std::path::Path)],
) -> Result<crate::output::RunDir> {
    for (flag, p) in inputs {
        if !p.exists() {
            bail!("{flag} {}: no such file or folder", p.display());
        }
    }
    let listed = inputs.iter().fold(crate::output::Inputs::new(), |acc, (f, p)| acc.add(f, p));
    listed.check(out)?;
    if resume && !out.join(state).is_file() {
        bail!("--resume: {} has no checkpoint ({state})", out.display());
    }
    Ok(crate::output::RunDir::prepare(out, &listed, resume, force, state)?)
}

/// The `data` entry of a world-model or autoencoder provenance file.
///
/// # Errors
/// A dataset whose attributes cannot be read.
pub fn data_provenance(path: &std::path::Path, episodes: usize, frames: usize) -> Result<FramesUsed> {
    Ok(FramesUsed::new(path, episodes, frames, dataset_origin(path)?))
}

/// The autoencoder and training settings the flags ask for; on `--resume`, checked against the
/// run's saved ones (a flag that contradicts them is refused).
///
/// # Errors
/// `--decoder-channels` that are not four multiples of 8, an unreadable saved config, or a
/// contradicting flag.
fn autoencoder_configs(a: &TrainAutoencoderArgs) -> Result<(AutoencoderConfig, AeTrainConfig)> {
    let decoder_channels = match a.decoder_channels.as_deref() {
        None => None,
        Some(&[c0, c1, c2, c3]) if [c0, c1, c2, c3].iter().all(|&c| c >= 8 && c % 8 == 0) => {
            Some([c0, c1, c2, c3])
        }
        Some(c) => {
            bail!("--decoder-channels {c:?}: four multiples of 8 (GroupNorm's 8 groups), e.g. 8,16,32,32")
        }
    };
    let model_cfg = AutoencoderConfig { decoder_channels, ..AutoencoderConfig::new() };
    let cfg = AeTrainConfig {
        steps: a.steps.unwrap_or(4000),
        batch: a.batch,
        lr: a.lr,
        seed: a.seed,
        eval_every: a.eval_every.max(1),
        checkpoint_every: a.checkpoint_every.max(1),
        encoder_from: a.encoder_from.clone(),
        ..AeTrainConfig::default()
    };
    if a.session.resume {
        let path = a.out.join("config.json");
        let saved: AeConfigs = read_configs(&path)?;
        let theirs = &saved.train;
        let fixed = [
            fixed("batch", &cfg.batch, &theirs.batch),
            fixed("lr", &cfg.lr, &theirs.lr),
            fixed("seed", &cfg.seed, &theirs.seed),
            fixed("eval_every", &cfg.eval_every, &theirs.eval_every),
            fixed("checkpoint_every", &cfg.checkpoint_every, &theirs.checkpoint_every),
            fixed("encoder_from", &cfg.encoder_from, &theirs.encoder_from),
            fixed("decoder_channels", &model_cfg.decoder_channels, &saved.model.decoder_channels),
        ];
        refuse_contradicting_flags(&path, "autoencoder", &fixed)?;
    }
    Ok((model_cfg, cfg))
}

/// `evalharness train autoencoder`.
pub fn autoencoder(a: &TrainAutoencoderArgs, quiet: bool) -> Result<ExitCode> {
    let mut inputs: Vec<(&str, &std::path::Path)> = vec![("--data", &a.data)];
    inputs.extend(a.encoder_from.as_deref().map(|p| ("--encoder-from", p)));
    let out_dir = prepare_out(&a.out, a.session.resume, a.session.force, "state.json", &inputs)?;
    let from_step = read_step(&a.out)?;
    let (model_cfg, cfg) = autoencoder_configs(a)?;
    tracing::info!(data = %a.data.display(), "loading frames");
    let data = EpisodeData::load(&a.data, model_cfg.image_size)?;
    // Read before training, so that unreadable attributes stop the run before it starts.
    let data_prov = data_provenance(&a.data, data.episodes.len(), data.len())?;
    tracing::info!(frames = data.len(), episodes = data.episodes.len(), "loaded");
    let args: Vec<String> = crate::stdout::command_line();
    open_session(&a.out, &args.join(" "), &super::git_commit(), from_step)?;
    let pb = progress::bar(cfg.steps, "autoencoder", quiet);
    let run = RunOptions {
        resume: a.session.resume,
        extend: a.steps.is_some(),
        max_minutes: a.session.max_minutes,
    };
    let outcome =
        train_autoencoder(&data, &a.out, &model_cfg, &cfg, run, &nn::device::selected()?, &mut |p| {
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
    let sessions = record_session(
        &a.out,
        &args.join(" "),
        &super::git_commit(),
        (from_step, outcome.step),
        outcome.elapsed_s,
    )?;
    // The saved config is the run's (a resumed run keeps it).
    let saved: AeConfigs = read_configs(&a.out.join("config.json"))?;
    let encoder_from = saved.train.encoder_from.as_ref().map(|dir| Source {
        path: dir.display().to_string(),
        provenance: harness::provenance::snapshot(dir),
    });
    let provenance = AutoencoderProvenance {
        command: args.join(" "),
        commit: super::git_commit(),
        data: data_prov,
        decoder_channels: saved.model.decoder_channels,
        elapsed_s: outcome.elapsed_s,
        finished: outcome.finished,
        metrics: AutoencoderMetrics { held_out_mse: Some(outcome.mse), held_out_psnr_db: Some(outcome.psnr) },
        seed: a.seed,
        sessions,
        steps: outcome.step,
        what: match &encoder_from {
            Some(_) => "frame decoder (12x12x8 -> 96x96x3) trained on a fixed encoder's latents",
            None => "frame autoencoder (96x96x3 <-> 12x12x8)",
        }
        .to_string(),
        encoder_from,
        other: Default::default(),
    };
    crate::output::write_json(&a.out.join("provenance.json"), &provenance)?;
    outln!(
        "autoencoder: step {}/{}{}, held-out PSNR {:.2} dB, MSE {:.6} -> {}",
        outcome.step,
        outcome.total,
        if outcome.finished { "" } else { " (stopped early; --resume continues)" },
        outcome.psnr,
        outcome.mse,
        a.out.display()
    );
    out_dir.finish(outcome.finished)?;
    Ok(ExitCode::SUCCESS)
}
