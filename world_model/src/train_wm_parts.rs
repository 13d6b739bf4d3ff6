//! The parts of the world-model trainer's loop (`train_wm`): the windows it trains and is
//! evaluated on, a warm start, a checkpoint saved and resumed, and one step's loss under
//! each objective. Tensor shapes: `b` contexts × `n` samples, `K` history and `F` future
//! frames of `C` × `s` × `s` latents.

use std::path::Path;

use burn::module::Module;
use burn::tensor::{Device, Distribution, Tensor};
use harness::seed::splitmix64;

use crate::data::{EpisodeData, Split};
use crate::drift_step::{DriftSetup, drifting_loss};
use crate::error::WorldModelError;
use crate::latents::{Latents, Window, window, window_starts};
use crate::model::{Objective, Prediction, WorldModelConfig, alpha_bar};
use crate::train_ae::{State, ckpt};
use crate::train_wm_config::WmTrainConfig;
use crate::unet::UNet;

/// The training windows' starts (`chunks` chunks long), the held-out windows the run is
/// evaluated on (one chunk, `cfg.eval_windows` of them evenly spread), and the action scale,
/// checked against the data.
///
/// # Errors
/// Episodes too short for a window in either split, or actions of another width.
pub(crate) fn windows_of(
    data: &EpisodeData,
    model_cfg: &WorldModelConfig,
    cfg: &WmTrainConfig,
    chunks: usize,
) -> Result<(Vec<usize>, Vec<Window>, crate::action::ActionScale), WorldModelError> {
    let (k, f) = (model_cfg.unet.history, model_cfg.future);
    let starts = window_starts(data, Split::Train, f * chunks);
    let held = window_starts(data, Split::HeldOut, f);
    if starts.is_empty() || held.is_empty() {
        return Err(WorldModelError::Data {
            path: data.source.clone(),
            message: format!("need episodes longer than {f} steps in both splits (every 10th is held out)"),
        });
    }
    let scale = model_cfg.action_scale();
    scale
        .check(data.action_dim)
        .map_err(|e| WorldModelError::Data { path: data.source.clone(), message: e.to_string() })?;
    let stride = (held.len() / cfg.eval_windows.max(1)).max(1);
    let eval_windows: Vec<Window> =
        held.iter().step_by(stride).take(cfg.eval_windows).map(|&t| window(data, t, k, f, &scale)).collect();
    Ok((starts, eval_windows, scale))
}

/// The U-Net a warm start (`--init-from DIR`) begins with: the other run's EMA weights, with
/// the layers this run adds (action maps, an anchor, a timestep embedding, accentuation;
/// new layers with zero output).
///
/// # Errors
/// A run whose U-Net this one cannot start from, or unreadable weights.
pub(crate) fn warm_start(
    dir: &Path,
    model_cfg: &WorldModelConfig,
    device: &Device,
) -> Result<UNet, WorldModelError> {
    // Warm start: both the trained and the EMA weights start from the other run's EMA;
    // a run may add action maps or a timestep embedding (new layers with zero output).
    let source = WorldModelConfig::read(dir)?.unet;
    if !model_cfg.unet.can_start_from(&source) {
        return Err(ckpt(&dir.join("config.json"), "its U-Net config differs from this run's"));
    }
    let path = dir.join("ema.bpk");
    let mut unet: UNet = source.init(device).try_load_file(&path).map_err(|e| ckpt(&path, e))?;
    if model_cfg.unet.uses_action_maps() {
        unet = unet.with_action_maps();
    }
    if model_cfg.unet.uses_anchor() {
        unet = unet.with_anchor();
    }
    if model_cfg.unet.timestep_embedding {
        unet = unet.with_timestep_embedding(device);
    }
    if model_cfg.unet.uses_accentuation() {
        unet = unet.with_accentuation(device);
    }
    Ok(unet)
}

/// Writes the trained and EMA weights, the optimiser and `state` as one checkpoint of `out`:
/// staged, then committed by a manifest.
///
/// # Errors
/// A file that cannot be written, naming it.
pub(crate) fn save_checkpoint(
    out: &Path,
    (unet, ema, optim): (&UNet, &UNet, &burn::optim::ModuleOptimizer),
    state: &State,
) -> Result<(), WorldModelError> {
    let mut stage = harness::checkpoint::begin(out, harness::checkpoint::MAIN)?;
    let p = ["model.bpk", "ema.bpk", "optimizer.bpk", "state.json"].map(|n| stage.path(n));
    unet.clone().save_file(&p[0]).map_err(|e| ckpt(&p[0], e))?;
    ema.clone().save_file(&p[1]).map_err(|e| ckpt(&p[1], e))?;
    optim.save(&p[2]).map_err(|e| ckpt(&p[2], e))?;
    harness::driver::write_state(&p[3], state)?;
    Ok(stage.commit()?)
}

/// What a step's loss is measured against: the batch's windows and their target frames'
/// latents (`chunks` chunks of a self-forcing rollout for drifting).
pub(crate) struct Targets<'a> {
    pub(crate) latents: &'a Latents<'a>,
    pub(crate) windows: &'a [Window],
    pub(crate) indices: &'a [usize],
    pub(crate) chunks: usize,
}

/// The step's loss under the run's objective, with the drifting loss's per-temperature
/// parts (empty for the baselines). `hist` `[b n, C, K, s, s]`, `anchor` `[b n, C, s, s]`,
/// `act` `[b n, F, action_dim]`; `rng` draws the diffusion baseline's timesteps.
pub(crate) fn objective_loss(
    unet: &UNet,
    (model_cfg, cfg): (&WorldModelConfig, &WmTrainConfig),
    (hist, anchor, act): (Tensor<5>, Option<Tensor<4>>, Tensor<3>),
    t: &Targets<'_>,
    rng: &mut u64,
) -> (Tensor<1>, Vec<f32>) {
    let (latents, windows, target_idx, chunks) = (t.latents, t.windows, t.indices, t.chunks);
    let (c, s, f) = (model_cfg.latents.channels, model_cfg.latents.size, model_cfg.future);
    let device = hist.device();
    let b = windows.len();
    let mut loss_r = Vec::new();
    let loss = match model_cfg.objective {
        Objective::Drifting => {
            let setup = DriftSetup {
                field: cfg.field,
                temperatures: &cfg.temperatures,
                motion: cfg.motion.as_ref(),
                chunks,
                accentuation: model_cfg.unet.uses_accentuation(),
            };
            let (loss, r) = drifting_loss(unet, latents, windows, hist, anchor, act, &setup);
            loss_r = r;
            loss
        }
        Objective::Mse => {
            let noise = Tensor::<5>::random([b, c, f, s, s], Distribution::Normal(0.0, 1.0), &device);
            let target = latents.tensor(target_idx, f, &device).swap_dims(1, 2); // [b, C, F, s, s]
            (unet.forward(noise, hist, act, anchor, None) - target).powf_scalar(2.0).mean()
        }
        Objective::Diffusion => {
            let x0 = latents.tensor(target_idx, f, &device).swap_dims(1, 2); // [b, C, F, s, s]
            let eps = Tensor::<5>::random([b, c, f, s, s], Distribution::Normal(0.0, 1.0), &device);
            let t: Vec<f32> = (0..b)
                .map(|_| {
                    *rng = splitmix64(*rng);
                    (*rng >> 11) as f32 / (1u64 << 53) as f32
                })
                .collect();
            let coef = |g: &dyn Fn(f64) -> f64| {
                let v: Vec<f32> = t.iter().map(|&t| g(alpha_bar(f64::from(t))) as f32).collect();
                Tensor::<1>::from_floats(v.as_slice(), &device).reshape([b, 1, 1, 1, 1])
            };
            let (sa, sb) = (coef(&|a| a.sqrt()), coef(&|a| (1.0 - a).sqrt()));
            let xt = x0.clone() * sa.clone() + eps.clone() * sb.clone();
            let target = match model_cfg.prediction.unwrap_or_default() {
                Prediction::V => eps * sa - x0 * sb,
                Prediction::X0 => x0,
            };
            let tt = Tensor::<1>::from_floats(t.as_slice(), &device);
            (unet.forward(xt, hist, act, anchor, Some(tt)) - target).powf_scalar(2.0).mean()
        }
    };
    (loss, loss_r)
}
/// A resumed run's checkpoint in `out`, recovered first if a save was cut short: the trained
/// and EMA weights (loaded into `unet` and `ema`), the optimiser and the state.
///
/// # Errors
/// An unreadable checkpoint file, naming it.
pub(crate) fn resume(
    out: &Path,
    (unet, ema, optim): (UNet, UNet, burn::optim::ModuleOptimizer),
) -> Result<(UNet, UNet, burn::optim::ModuleOptimizer, State), WorldModelError> {
    let paths = ["model.bpk", "ema.bpk", "optimizer.bpk", "state.json"].map(|p| out.join(p));
    harness::checkpoint::recover(out, harness::checkpoint::MAIN)?;
    let unet = unet.try_load_file(&paths[0]).map_err(|e| ckpt(&paths[0], e))?;
    let ema = ema.try_load_file(&paths[1]).map_err(|e| ckpt(&paths[1], e))?;
    let optim = optim.load(&paths[2]).map_err(|e| ckpt(&paths[2], e))?;
    let state = harness::driver::read_state(&paths[3])?;
    Ok((unet, ema, optim, state))
}

/// `contexts` training windows of `k` history and `span` target frames, each at a start
/// drawn from `rng` (the step's stream, which the diffusion baseline's timesteps continue).
pub(crate) fn draw_windows(
    data: &EpisodeData,
    starts: &[usize],
    (contexts, k, span): (usize, usize, usize),
    scale: &crate::action::ActionScale,
    rng: &mut u64,
) -> Vec<Window> {
    (0..contexts)
        .map(|_| {
            *rng = splitmix64(*rng);
            window(data, starts[(*rng % starts.len() as u64) as usize], k, span, scale)
        })
        .collect()
}
