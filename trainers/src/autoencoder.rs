//! `evalharness train autoencoder`: the frame autoencoder whose latents the world model
//! works in, its filmstrip of held-out reconstructions, and its provenance.

use crate::error::{Result, refuse};
use crate::{Invocation, say};
use harness::provenance::{AutoencoderMetrics, AutoencoderProvenance, Source};
use world_model::autoencoder::AutoencoderConfig;
use world_model::data::EpisodeData;
use world_model::train_ae::{AeConfigs, AeTrainConfig, RunOptions, read_configs, train_autoencoder};

use crate::args::TrainAutoencoderArgs;
use crate::common::{data_provenance, fixed, prepare_out, refuse_contradicting_flags};
use harness::sessions::{open_session, read_step, record_session};
use runner::command::write_json;

/// The autoencoder and training settings the flags ask for; on `--resume`, checked against the
/// run's saved ones (a flag that contradicts them is refused).
///
/// # Errors
/// `--decoder-channels` that are not four multiples of 8, an unreadable saved config, or a
/// contradicting flag.
fn autoencoder_configs(
    a: &TrainAutoencoderArgs,
    given: &[String],
) -> Result<(AutoencoderConfig, AeTrainConfig)> {
    let decoder_channels = match a.decoder_channels.as_deref() {
        None => None,
        Some(&[c0, c1, c2, c3]) if [c0, c1, c2, c3].iter().all(|&c| c >= 8 && c % 8 == 0) => {
            Some([c0, c1, c2, c3])
        }
        Some(c) => {
            refuse!("--decoder-channels {c:?}: four multiples of 8 (GroupNorm's 8 groups), e.g. 8,16,32,32")
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
        refuse_contradicting_flags(&path, given, &fixed)?;
    }
    Ok((model_cfg, cfg))
}

/// `evalharness train autoencoder`.
pub fn autoencoder(a: &TrainAutoencoderArgs, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<()> {
    let mut inputs: Vec<(&str, &std::path::Path)> = vec![("--data", &a.data)];
    inputs.extend(a.encoder_from.as_deref().map(|p| ("--encoder-from", p)));
    let out_dir = prepare_out(&a.out, a.session.resume, a.session.force, "state.json", &inputs)?;
    let from_step = read_step(&a.out)?;
    let (model_cfg, cfg) = autoencoder_configs(a, &inv.given)?;
    tracing::info!(data = %a.data.display(), "loading frames");
    let data = EpisodeData::load(&a.data, model_cfg.image_size)?;
    // Read before training, so that unreadable attributes stop the run before it starts.
    let data_prov = data_provenance(&a.data, data.episodes.len(), data.len())?;
    tracing::info!(frames = data.len(), episodes = data.episodes.len(), "loaded");
    let args: Vec<String> = inv.command_line.clone();
    open_session(&a.out, &args.join(" "), &inv.commit, from_step)?;
    let pb = runner::progress::bar(cfg.steps, "autoencoder", inv.quiet);
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
    let sessions =
        record_session(&a.out, &args.join(" "), &inv.commit, (from_step, outcome.step), outcome.elapsed_s)?;
    // The saved config is the run's (a resumed run keeps it).
    let saved: AeConfigs = read_configs(&a.out.join("config.json"))?;
    let encoder_from = saved.train.encoder_from.as_ref().map(|dir| Source {
        path: dir.display().to_string(),
        provenance: harness::provenance::snapshot(dir),
    });
    let provenance = AutoencoderProvenance {
        command: args.join(" "),
        commit: inv.commit.clone(),
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
    write_json(&a.out.join("provenance.json"), &provenance)?;
    say!(
        say,
        "autoencoder: step {}/{}{}, held-out PSNR {:.2} dB, MSE {:.6} -> {}",
        outcome.step,
        outcome.total,
        if outcome.finished { "" } else { " (stopped early; --resume continues)" },
        outcome.psnr,
        outcome.mse,
        a.out.display()
    );
    out_dir.finish(outcome.finished)?;
    Ok(())
}
