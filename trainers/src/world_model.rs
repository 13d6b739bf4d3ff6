//! `evalharness train world-model`: trains the DriftWorld U-Net (or the MSE or
//! diffusion baseline) on a trained autoencoder's latents (`--config
//! pusht-latent`, the default) or on pixels (`--config pusht-pixel`, the paper's
//! model), and writes the run's provenance.

use std::path::{Component, Path, PathBuf};

use crate::error::{Context, Result, refuse};
use crate::{Invocation, say};
use burn::tensor::Device;
use harness::provenance::{WorldModelMetrics, WorldModelProvenance};
use scenarios::pusht::goal_free::{self, DatasetScene};
use world_model::codec::FrameCodec;
use world_model::data::EpisodeData;
use world_model::drift_step::FieldKind;
use world_model::latents::Latents;
use world_model::model::{Objective, WorldModelConfig};
use world_model::motion::MotionWeighting;
use world_model::train_ae::RunOptions;
use world_model::train_wm::{TrainingFrames, WmTrainConfig, train_world_model};
use world_model::unet::UNetConfig;

use crate::args::{FieldArg, PredictionArg, TrainWorldModelArgs, WmConfigArg};
use crate::common::{data_provenance, prepare_out};
use crate::wm_inputs::{
    check_resume_flags, fresh_codec, fresh_objective, fresh_prediction, resumed_codec, same_folder,
    set_saved_ema_decay, warm_start_record, warm_start_stats,
};
use harness::sessions::{open_session, read_step, record_session};
use runner::command::write_json;

/// `target` relative to the folder `base` (both must exist), e.g. `../autoencoder`.
pub fn relative_to(base: &Path, target: &Path) -> Result<PathBuf> {
    let b = base.canonicalize().with_context(|| format!("resolving {}", base.display()))?;
    let t = target.canonicalize().with_context(|| format!("resolving {}", target.display()))?;
    let (bc, tc): (Vec<Component>, Vec<Component>) = (b.components().collect(), t.components().collect());
    let common = bc.iter().zip(&tc).take_while(|(x, y)| x == y).count();
    let mut rel = PathBuf::new();
    for _ in common..bc.len() {
        rel.push("..");
    }
    for c in &tc[common..] {
        rel.push(c);
    }
    Ok(rel)
}

/// The inference α of an accentuated model when `--alpha` is not given (the
/// authors' RT-1 evaluation setting, spec §3).
const DEFAULT_ALPHA: f32 = 2.5;

/// How a new model reads the dataset's actions: Push-T's world units (recorded as
/// absent, as in every Push-T model) or the bounds of the action space of the task
/// the dataset was collected in (its attributes name it).
///
/// # Errors
/// A task that cannot be loaded, or actions of another width than the task's.
fn action_scale_of(data: &Path, action_dim: usize) -> Result<Option<world_model::action::ActionScale>> {
    let task = crate::common::dataset_task(data)?;
    let scenario = task.name();
    let spec = (scenario != "pusht").then(|| task.action_spec());
    let expected = spec.as_ref().map_or(2, |s| s.dim);
    if action_dim != expected {
        refuse!("{}: actions of {action_dim} entries, a {scenario} task's have {expected}", data.display());
    }
    Ok(spec.map(|s| world_model::action::ActionScale { low: s.low, high: s.high }))
}

/// The training settings the flags ask for, every flag checked against the others (before
/// `--force` clears the output folder, so a refused run keeps it).
///
/// # Errors
/// A flag out of range, or one that the objective, field or other flags rule out.
fn train_config(a: &TrainWorldModelArgs, objective: Objective) -> Result<WmTrainConfig> {
    let defaults = WmTrainConfig::for_objective(objective);
    let cfg = WmTrainConfig {
        steps: a.steps.unwrap_or(defaults.steps),
        contexts: a.contexts.unwrap_or(defaults.contexts),
        samples: if objective == Objective::Drifting { a.samples.unwrap_or(defaults.samples) } else { 1 },
        lr: a.lr,
        warmup: a.warmup,
        seed: a.seed,
        eval_every: a.eval_every.max(1),
        eval_windows: a.eval_windows.max(1),
        checkpoint_every: a.checkpoint_every.max(1),
        field: match a.field {
            FieldArg::Frame => FieldKind::Frame,
            FieldArg::Token => FieldKind::Token,
        },
        init_from: a.init_from.clone(),
        motion: a.motion_weighting.then(MotionWeighting::default),
        chunks: a.self_forcing,
        context_noise: a.context_noise,
        ema_decay: a.ema_decay.unwrap_or(defaults.ema_decay),
        ..defaults
    };
    if !(0.0..1.0).contains(&cfg.ema_decay) {
        refuse!("--ema-decay: needs a value in [0, 1), got {}", cfg.ema_decay);
    }
    if !(a.context_noise.is_finite() && a.context_noise >= 0.0) {
        refuse!("--context-noise: needs a finite level >= 0, got {}", a.context_noise);
    }
    if a.self_forcing == 0 || (a.self_forcing > 1 && objective != Objective::Drifting) {
        refuse!("--self-forcing: needs a chunk count >= 1, and more than 1 only with --objective drifting");
    }
    if cfg.motion.is_some() && (objective != Objective::Drifting || cfg.field != FieldKind::Token) {
        refuse!(
            "--motion-weighting weighs per-token drifting losses: it needs --objective drifting --field token"
        );
    }
    if !a.session.resume && a.prediction != PredictionArg::V && objective != Objective::Diffusion {
        refuse!("--prediction chooses the diffusion baseline's output: it needs --objective diffusion");
    }
    if !a.session.resume && a.accentuation && objective != Objective::Drifting {
        refuse!(
            "--accentuation adds a weighted negative to the drifting loss: it needs --objective drifting"
        );
    }
    if let Some(alpha) = a.alpha
        && (!a.accentuation || !alpha.is_finite() || alpha < 1.0)
    {
        refuse!(
            "--alpha: the inference strength of an --accentuation model, a finite value >= 1 (got {alpha})"
        );
    }
    if objective == Objective::Drifting && cfg.samples < 2 {
        refuse!(
            "--samples: drifting needs at least 2 samples per context (the other samples are the negatives)"
        );
    }
    if let (false, Some(dir)) = (a.session.resume, &a.init_from) {
        // Checked before --force clears the output folder, so a refused run keeps it.
        WorldModelConfig::read(dir).with_context(|| format!("--init-from {}", dir.display()))?;
        if !dir.join("ema.bpk").is_file() {
            refuse!("--init-from {}: no ema.bpk (not a world-model run or export)", dir.display());
        }
        if same_folder(dir, &a.out) {
            refuse!("--init-from {} is the output folder itself", dir.display());
        }
    }
    Ok(cfg)
}

/// A fresh run's world-model configuration: the U-Net the flags ask for on `data`'s actions,
/// the latents' statistics (measured through `codec`, or the warm start's), and the sampling
/// settings.
///
/// # Errors
/// Flags the data or the family rule out, or a warm start that cannot be read.
fn fresh_model_config(
    a: &TrainWorldModelArgs,
    objective: Objective,
    data: &EpisodeData,
    codec: &FrameCodec,
    inner: &Device,
) -> Result<WorldModelConfig> {
    let actions = action_scale_of(&a.data, data.action_dim)?;
    if actions.is_some() && a.action_maps {
        refuse!(
            "--action-maps draws Push-T's 2-D targets onto the frame; {} holds other actions",
            a.data.display()
        );
    }
    let family = match a.config {
        WmConfigArg::PushtLatent => UNetConfig::pusht_latent(codec.channels()),
        WmConfigArg::PushtPixel => UNetConfig::pusht_pixel(),
    };
    let unet = UNetConfig {
        model_channels: a.base_channels.unwrap_or(match a.config {
            WmConfigArg::PushtLatent => 32,
            WmConfigArg::PushtPixel => family.model_channels,
        }),
        timestep_embedding: objective == Objective::Diffusion,
        action_maps: a.action_maps.then_some(true),
        anchor: a.anchor.then_some(true),
        accentuation: a.accentuation.then_some(true),
        action_dim: data.action_dim,
        ..family
    };
    if let Err(e) = unet.check() {
        refuse!("--base-channels {}: {e}", unet.model_channels);
    }
    let stats = match &a.init_from {
        Some(dir) => warm_start_stats(dir, &unet, a.autoencoder.as_deref())?,
        None => {
            tracing::info!("measuring the encoded frames' statistics");
            Latents::measure_stats(data, codec, 2048, inner)
        }
    };
    let autoencoder = match &a.autoencoder {
        Some(ae) => Some(relative_to(&a.out, ae)?),
        None => None,
    };
    Ok(WorldModelConfig {
        objective,
        unet,
        latents: stats,
        autoencoder,
        future: 4,
        sample_steps: if objective == Objective::Diffusion { a.sample_steps.max(1) } else { 1 },
        prediction: fresh_prediction(a),
        alpha: a.accentuation.then_some(a.alpha.unwrap_or(DEFAULT_ALPHA)),
        goal_free: a.goal_free.then_some(true),
        actions,
        noise_scale: None,
    })
}

/// `evalharness train world-model`.
pub fn run(a: &TrainWorldModelArgs, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<()> {
    let objective = fresh_objective(a.objective);
    let cfg = train_config(a, objective)?;
    let mut inputs: Vec<(&str, &Path)> = vec![("--data", &a.data)];
    inputs.extend(a.autoencoder.as_deref().map(|p| ("--autoencoder", p)));
    inputs.extend(a.init_from.as_deref().map(|p| ("--init-from", p)));
    let out_dir = prepare_out(&a.out, a.session.resume, a.session.force, "state.json", &inputs)?;
    let from_step = read_step(&a.out)?;
    if a.session.resume {
        check_resume_flags(a, &cfg, &inv.given)?;
    }
    if let (true, Some(decay)) = (a.session.resume, a.ema_decay) {
        set_saved_ema_decay(&a.out, decay)?;
    }
    let inner = nn::device::selected()?;
    // A resumed run keeps its saved config (and so its codec); a fresh one builds it.
    let saved = if a.session.resume { Some(WorldModelConfig::read(&a.out)?) } else { None };
    let codec = match &saved {
        Some(saved) => resumed_codec(a, saved, &inner)?,
        None => fresh_codec(a, &inner)?,
    };
    tracing::info!(data = %a.data.display(), "loading frames");
    let mut data = EpisodeData::load(&a.data, codec.image_size())?;
    // Read before training, so that unreadable attributes stop the run before it starts.
    let data_prov = data_provenance(&a.data, data.episodes.len(), data.len())?;
    tracing::info!(frames = data.len(), episodes = data.episodes.len(), "loaded");
    let goal_free = saved.as_ref().map_or(a.goal_free, WorldModelConfig::is_goal_free);
    if goal_free {
        tracing::info!("re-rendering the frames without the goal (from data/state)");
        let scene = DatasetScene::load(&a.data)?;
        let size = data.size;
        goal_free::strip_goal(&a.data, &scene, &mut data.frames, size)?;
    }
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let model_cfg = match saved {
        Some(saved) => saved,
        None => fresh_model_config(a, objective, &data, &codec, &inner)?,
    };
    let args: Vec<String> = inv.command_line.clone();
    open_session(&a.out, &args.join(" "), &inv.commit, from_step)?;
    let pb = runner::progress::bar(cfg.steps, objective.name(), inv.quiet);
    let run = RunOptions {
        resume: a.session.resume,
        extend: a.steps.is_some(),
        max_minutes: a.session.max_minutes,
    };
    let outcome = train_world_model(
        TrainingFrames { data: &data, codec: &codec },
        &a.out,
        &model_cfg,
        &cfg,
        run,
        &inner,
        &mut |p| {
            pb.set_length(p.total);
            pb.set_position(p.step);
            let lr: Vec<String> = p.loss_r.iter().map(|v| format!("{v:.3}")).collect();
            let eval = p.eval_mse.map_or(String::new(), |m| format!(" eval {m:.4}"));
            pb.set_message(format!("loss {:.4} loss_R [{}]{eval}", p.loss, lr.join(" ")));
        },
    )?;
    pb.finish_and_clear();
    let sessions =
        record_session(&a.out, &args.join(" "), &inv.commit, (from_step, outcome.step), outcome.elapsed_s)?;
    let saved = WorldModelConfig::read(&a.out)?;
    let provenance = provenance(a, inv, (&saved, goal_free), data_prov, (&outcome, sessions))?;
    write_json(&a.out.join("provenance.json"), &provenance)?;
    say!(
        say,
        "world model ({}): step {}/{}{}, held-out one-chunk latent MSE {:.5} -> {}",
        saved.objective.name(),
        outcome.step,
        outcome.total,
        if outcome.finished { "" } else { " (stopped early; --resume continues)" },
        outcome.eval_mse,
        a.out.display()
    );
    out_dir.finish(outcome.finished)?;
    Ok(())
}

/// The run's `provenance.json`: the command and commit, the data, the frames it saw, the
/// warm start, the sessions and the held-out error at the end.
///
/// # Errors
/// The run's saved configuration, or the warm start's provenance, unreadable.
fn provenance(
    a: &TrainWorldModelArgs,
    inv: &Invocation,
    (saved, goal_free): (&WorldModelConfig, bool),
    data_prov: harness::provenance::FramesUsed,
    (outcome, sessions): (&world_model::train_wm::WmOutcome, Vec<harness::sessions::Session>),
) -> Result<WorldModelProvenance> {
    let frames = if goal_free {
        "re-rendered without the goal from data/state (--goal-free)"
    } else {
        "data/img as stored"
    };
    Ok(WorldModelProvenance {
        autoencoder: saved.autoencoder.as_ref().map(|ae| ae.display().to_string()),
        autoencoder_replaced: None,
        command: inv.command_line.join(" "),
        commit: inv.commit.clone(),
        data: data_prov,
        elapsed_s: outcome.elapsed_s,
        exported: Vec::new(),
        finished: outcome.finished,
        frames: Some(frames.to_string()),
        init_from: warm_start_record(&a.out)?,
        metrics: WorldModelMetrics { held_out_one_chunk_latent_mse: Some(outcome.eval_mse) },
        seed: a.seed,
        sessions,
        steps: outcome.step,
        what: format!(
            "world model U-Net, objective {}, on {}",
            saved.objective.name(),
            saved
                .autoencoder
                .as_ref()
                .map_or("pixels".into(), |ae| format!("the latents of {}", ae.display()))
        ),
        other: Default::default(),
    })
}
