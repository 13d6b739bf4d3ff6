//! What a `train world-model` run reads besides its data: the codec (an autoencoder's
//! latents, or pixels), the run it warm-starts from, and on `--resume` the saved settings
//! the flags typed must agree with.

use std::path::Path;

use burn::tensor::Device;
use harness::provenance::Source;
use world_model::codec::FrameCodec;
use world_model::latents::LatentStats;
use world_model::model::{Objective, Prediction, WorldModelConfig};
use world_model::train_ae::read_configs;
use world_model::train_wm::{WmConfigs, WmTrainConfig};
use world_model::unet::UNetConfig;

use crate::args::{ObjectiveArg, PredictionArg, TrainWorldModelArgs, WmConfigArg};
use crate::common::{fixed, refuse_contradicting_flags};
use crate::error::{Context, Result, refuse};
use runner::command::{read_json, write_json};

/// The diffusion parameterisation `--prediction` names.
fn prediction(a: &TrainWorldModelArgs) -> Prediction {
    match a.prediction {
        PredictionArg::V => Prediction::V,
        PredictionArg::X0 => Prediction::X0,
    }
}

/// What a fresh run records: the parameterisation for diffusion, none otherwise.
pub(crate) fn fresh_prediction(a: &TrainWorldModelArgs) -> Option<Prediction> {
    (a.objective == ObjectiveArg::Diffusion).then_some(prediction(a))
}

/// The objective `--objective` names.
pub(crate) fn fresh_objective(o: ObjectiveArg) -> Objective {
    match o {
        ObjectiveArg::Drifting => Objective::Drifting,
        ObjectiveArg::Mse => Objective::Mse,
        ObjectiveArg::Diffusion => Objective::Diffusion,
    }
}

/// The codec of a fresh run: `--config` and `--autoencoder` must agree.
pub(crate) fn fresh_codec(a: &TrainWorldModelArgs, device: &Device) -> Result<FrameCodec> {
    match (a.config, &a.autoencoder) {
        (WmConfigArg::PushtLatent, Some(ae)) => Ok(FrameCodec::autoencoder(ae, device)?),
        (WmConfigArg::PushtLatent, None) => {
            refuse!("--config pusht-latent trains on autoencoder latents: pass --autoencoder DIR")
        }
        (WmConfigArg::PushtPixel, None) => Ok(FrameCodec::pixels(96)),
        (WmConfigArg::PushtPixel, Some(_)) => {
            refuse!("--config pusht-pixel trains on pixels: it takes no --autoencoder")
        }
    }
}

/// The codec of a resumed run: its saved one, which `--autoencoder` (if given) must name.
pub(crate) fn resumed_codec(
    a: &TrainWorldModelArgs,
    saved: &WorldModelConfig,
    device: &Device,
) -> Result<FrameCodec> {
    let theirs = saved.autoencoder.as_ref().map(|p| a.out.join(p));
    match (&theirs, &a.autoencoder) {
        (Some(t), Some(o)) if !same_folder(t, o) => refuse!(
            "--resume: {} was trained on the autoencoder {}, not {}",
            a.out.display(),
            t.display(),
            o.display()
        ),
        (None, Some(o)) => refuse!(
            "--resume: {} is a pixel-space model, it takes no --autoencoder (got {})",
            a.out.display(),
            o.display()
        ),
        _ => {}
    }
    saved.codec(&a.out, device).with_context(|| format!("--resume {}", a.out.display()))
}

/// Whether two paths name the same existing folder.
pub(crate) fn same_folder(x: &Path, y: &Path) -> bool {
    x.canonicalize().ok().zip(y.canonicalize().ok()).is_some_and(|(x, y)| x == y)
}

/// The latent statistics of the run `dir` that `--init-from` starts from, after
/// checking that its U-Net and autoencoder are the ones this run uses.
pub(crate) fn warm_start_stats(
    dir: &Path,
    unet: &UNetConfig,
    autoencoder: Option<&Path>,
) -> Result<LatentStats> {
    let from = WorldModelConfig::read(dir).context("--init-from")?;
    // The differences a warm start bridges: adding action maps or a timestep embedding.
    if !unet.can_start_from(&from.unet) {
        refuse!(
            "--init-from {}: its U-Net config differs from this run's ({:?} vs {:?})",
            dir.display(),
            from.unet,
            unet
        );
    }
    let theirs = from.autoencoder.as_ref().map(|p| dir.join(p));
    let same = match (&theirs, autoencoder) {
        (Some(t), Some(o)) => same_folder(t, o),
        (None, None) => true,
        _ => false,
    };
    if !same {
        let name =
            |p: Option<&Path>| p.map_or("pixels".to_string(), |p| format!("autoencoder {}", p.display()));
        refuse!(
            "--init-from {}: it was trained on {}, this run on {}",
            dir.display(),
            name(theirs.as_deref()),
            name(autoencoder)
        );
    }
    Ok(from.latents)
}

/// Where a warm-started run came from: its folder, with the source run's provenance as
/// it was when this run first recorded it (snapshotted into
/// `OUT/init_from_provenance.json`, since the source may go on training), so a shipped
/// model's lineage nests all the way back; `None` for a cold start.
pub(crate) fn warm_start_record(out: &Path) -> Result<Option<Source>> {
    let saved: WmConfigs = read_configs(&out.join("config.json"))?;
    let Some(src) = saved.train.init_from else {
        return Ok(None);
    };
    let path = src.display().to_string();
    let snapshot = out.join("init_from_provenance.json");
    if !snapshot.exists() {
        match read_json(&src.join("provenance.json")) {
            Ok(v) => write_json(&snapshot, &v)?,
            Err(e) => {
                tracing::warn!("--init-from {path}: no provenance to record ({e:#})");
                return Ok(Some(Source { path, provenance: None }));
            }
        }
    }
    Ok(Some(Source { path, provenance: Some(read_json(&snapshot)?) }))
}

/// `--resume --ema-decay D`: the run goes on with decay D (its EMA weights as
/// they are), written into its `config.json` so the change is on record.
pub(crate) fn set_saved_ema_decay(out: &Path, decay: f64) -> Result<()> {
    let path = out.join("config.json");
    let mut saved: WmConfigs = read_configs(&path)?;
    let before = saved.train.ema_decay;
    if before != decay {
        tracing::info!(before, after = decay, "changing the EMA decay");
        saved.train.ema_decay = decay;
        harness::runfile::write_config(&path, &saved)?;
    }
    Ok(())
}

/// `--resume` continues a run with its saved `config.json`: the model and loss flags
/// typed on this command line must agree with it (`--steps`, `--ema-decay` and the
/// session flags may change; see [`refuse_contradicting_flags`]).
pub(crate) fn check_resume_flags(
    a: &TrainWorldModelArgs,
    fresh: &WmTrainConfig,
    given: &[String],
) -> Result<()> {
    let path = a.out.join("config.json");
    let WmConfigs { model, train } = read_configs(&path)?;
    // The same starting folder, however it is spelt, is no contradiction.
    let init_from = match (&fresh.init_from, &train.init_from) {
        (Some(x), Some(y)) if x == y || same_folder(x, y) => &train.init_from,
        _ => &fresh.init_from,
    };
    let family = |pixels: bool| if pixels { "pusht-pixel" } else { "pusht-latent" };
    let fixed = [
        fixed("contexts", &fresh.contexts, &train.contexts),
        fixed("samples", &fresh.samples, &train.samples),
        fixed("field", &fresh.field, &train.field),
        fixed("warmup", &fresh.warmup, &train.warmup),
        fixed("lr", &fresh.lr, &train.lr),
        fixed("seed", &fresh.seed, &train.seed),
        fixed("eval_every", &fresh.eval_every, &train.eval_every),
        fixed("eval_windows", &fresh.eval_windows, &train.eval_windows),
        fixed("checkpoint_every", &fresh.checkpoint_every, &train.checkpoint_every),
        fixed("self_forcing", &fresh.chunks, &train.chunks),
        fixed("context_noise", &fresh.context_noise, &train.context_noise),
        fixed("motion_weighting", &a.motion_weighting, &train.motion.is_some()),
        fixed("init_from", init_from, &train.init_from),
        fixed("objective", &fresh_objective(a.objective).name(), &model.objective.name()),
        fixed(
            "config",
            &family(matches!(a.config, WmConfigArg::PushtPixel)),
            &family(model.autoencoder.is_none()),
        ),
        fixed("base_channels", &a.base_channels, &Some(model.unet.model_channels)),
        fixed("action_maps", &a.action_maps, &model.unet.uses_action_maps()),
        fixed("anchor", &a.anchor, &model.unet.uses_anchor()),
        fixed("goal_free", &a.goal_free, &model.is_goal_free()),
        fixed("accentuation", &a.accentuation, &model.unet.uses_accentuation()),
        fixed("sample_steps", &a.sample_steps, &model.sample_steps),
        fixed("prediction", &prediction(a), &model.prediction.unwrap_or_default()),
    ];
    refuse_contradicting_flags(&path, given, &fixed)
}
