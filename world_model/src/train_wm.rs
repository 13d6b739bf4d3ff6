//! Training the world model's U-Net on autoencoder latents with one of three
//! objectives (drifting, one-step MSE, multi-step diffusion), resumable and
//! time-boxed like the autoencoder's trainer (spec §6).
//!
//! One drifting step: B contexts, each repeated N times with fresh noise; the U-Net
//! predicts F frames per clip in one pass; each (context, future frame) — or, with
//! [`FieldKind::Token`](crate::drift_step::FieldKind::Token), each (context, future
//! frame, latent cell) — is its own drift problem with the N generated samples as
//! negatives and the truth as the single positive. AdamW β = (0.9, 0.95), weight decay 0.01, linear warm-up then a
//! constant rate, global grad-norm clip, EMA of the weights (all sampling uses it).
//!
//! Output folder: `config.json` (model + training config), `model.bpk`, `ema.bpk`,
//! `optimizer.bpk`, `state.json`, `train_log.jsonl`.

use std::path::Path;

use burn::module::Module;
use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use harness::driver::{Clock, Driver};
use harness::rng::Rng;
use harness::seed::derive;
use serde_json::json;

use crate::codec::FrameCodec;
use crate::data::EpisodeData;
use crate::error::WorldModelError;
use crate::latents::{Latents, Window};
use crate::model::{Objective, WorldModel, WorldModelConfig};
use crate::train_ae::{Configs, RunOptions, State, finite, run_configs};
use crate::train_wm_parts::{
    Targets, draw_windows, objective_loss, resume, save_checkpoint, warm_start, windows_of,
};
use crate::unet::UNet;
use nn::optim::{Ema, clip_global_norm, warmup_lr};

pub use crate::train_wm_config::{WmConfigs, WmTrainConfig};

/// A training progress report.
#[derive(Clone, Debug)]
pub struct WmProgress {
    /// Steps done.
    pub step: u64,
    /// Steps in total.
    pub total: u64,
    /// Last batch loss.
    pub loss: f64,
    /// Per-temperature `loss_R` (drifting only).
    pub loss_r: Vec<f32>,
    /// Last held-out one-chunk latent MSE.
    pub eval_mse: Option<f64>,
}

/// What a (possibly time-limited) run ended with.
#[derive(Clone, Debug)]
pub struct WmOutcome {
    /// Steps done.
    pub step: u64,
    /// Steps configured.
    pub total: u64,
    /// Whether all configured steps are done.
    pub finished: bool,
    /// Held-out one-chunk latent MSE of the EMA model at the end.
    pub eval_mse: f64,
    /// Wall seconds over all sessions.
    pub elapsed_s: f64,
}

/// The episodes to train on and the codec that maps their frames to the U-Net's space.
#[derive(Clone, Copy)]
pub struct TrainingFrames<'a> {
    /// Frames, actions and episode boundaries.
    pub data: &'a EpisodeData,
    /// Autoencoder or pixels, as the model config names.
    pub codec: &'a FrameCodec,
}

/// Windows stacked for a batch, each repeated `repeat` times.
struct Stacked {
    /// `[b·K]` history frame indices.
    hist: Vec<usize>,
    /// `[b·F]` target frame indices.
    targets: Vec<usize>,
    /// `[b]` anchor frame indices (each episode's first frame).
    anchors: Vec<usize>,
    /// `[b, F, action_dim]` normalised actions.
    act: Tensor<3>,
}

fn stack(windows: &[Window], repeat: usize, device: &Device) -> Stacked {
    let (mut hist, mut targets, mut anchors, mut acts) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for w in windows {
        for _ in 0..repeat {
            hist.extend_from_slice(&w.history);
            targets.extend_from_slice(&w.targets);
            anchors.push(w.anchor);
            acts.extend_from_slice(&w.actions);
        }
    }
    let f = windows.first().map_or(0, |w| w.targets.len());
    let d = windows.first().map_or(0, |w| w.actions.len() / w.targets.len().max(1));
    let act = Tensor::from_data(TensorData::new(acts, [windows.len() * repeat, f, d]), device);
    Stacked { hist, targets, anchors, act }
}

/// The anchors' normalised latents `[b, C, s, s]` (already encoded).
fn anchor_tensor(latents: &Latents, anchors: &[usize], device: &Device) -> Tensor<4> {
    let z = latents.tensor(anchors, 1, device); // [b, 1, C, s, s]
    let [b, _, c, s, _] = z.dims();
    z.reshape([b, c, s, s])
}

/// Held-out one-chunk latent MSE of `model` on `windows` (fixed noise seeds).
fn evaluate(model: &WorldModel, latents: &mut Latents, codec: &FrameCodec, windows: &[Window]) -> f64 {
    let device = model.device().clone();
    let (k, f) = (windows[0].history.len(), windows[0].targets.len());
    let st = stack(windows, 1, &device);
    for idx in [&st.hist, &st.targets, &st.anchors] {
        latents.ensure(idx, codec, &device);
    }
    let mut rngs: Vec<Rng> = (0..windows.len()).map(|i| Rng::new(i as u64)).collect();
    let anchor = anchor_tensor(latents, &st.anchors, &device);
    let pred = model.predict(latents.tensor(&st.hist, k, &device), anchor, st.act, &mut rngs);
    let truth = latents.tensor(&st.targets, f, &device);
    (pred - truth).powf_scalar(2.0).mean().into_scalar::<f32>().into()
}

/// The world model's steps for the shared loop ([`Driver::train`]): B contexts' windows
/// drawn from `(seed, step)`, the objective's loss, a clipped AdamW step and the EMA; the
/// held-out MSE every `eval_every` steps, a checkpoint every `checkpoint_every`.
struct WmSteps<'a, 'd> {
    frames: TrainingFrames<'a>,
    configs: (&'a WorldModelConfig, &'a WmTrainConfig),
    out: &'a Path,
    /// The autodiff device training runs on, and its inner one for evaluation.
    devices: (&'a Device, &'a Device),
    /// The training windows' starts, the held-out windows, the action scale.
    windows: (&'a [usize], &'a [Window], &'a crate::action::ActionScale),
    latents: &'a mut Latents<'d>,
    ema: &'a mut Ema<UNet>,
    state: State,
    /// The last step's loss and per-frame losses, and the last held-out MSE.
    last: (f64, Vec<f32>, Option<f64>),
    on_progress: &'a mut dyn FnMut(&WmProgress),
}

impl WmSteps<'_, '_> {
    /// The EMA weights' one-chunk latent MSE on the held-out windows.
    fn held_out_mse(&mut self) -> f64 {
        let ((model_cfg, _), (_, inner)) = (self.configs, self.devices);
        let codec = self.frames.codec;
        let model = WorldModel::from_parts(model_cfg.clone(), codec.clone(), self.ema.module.clone(), inner);
        evaluate(&model, self.latents, codec, self.windows.1)
    }
}

impl harness::driver::Steps for WmSteps<'_, '_> {
    type Net = (UNet, burn::optim::ModuleOptimizer);
    type Line = serde_json::Value;
    type Error = WorldModelError;

    fn done(&self) -> u64 {
        self.state.step
    }

    fn total(&self) -> u64 {
        self.configs.1.steps
    }

    fn step(
        &mut self,
        (unet, mut optim): Self::Net,
        elapsed_s: &dyn Fn() -> f64,
    ) -> harness::driver::Stepped<Self> {
        let ((model_cfg, cfg), (device, inner)) = (self.configs, self.devices);
        let TrainingFrames { data, codec } = self.frames;
        let (starts, _, scale) = self.windows;
        let objective = model_cfg.objective;
        let (k, f) = (model_cfg.unet.history, model_cfg.future);
        let chunks = if objective == Objective::Drifting { cfg.chunks.max(1) } else { 1 };
        let step = self.state.step;
        let mut rng = derive(cfg.seed, &[step]);
        let windows = draw_windows(data, starts, (cfg.contexts, k, f * chunks), scale, &mut rng);
        let n = if objective == Objective::Drifting { cfg.samples } else { 1 };
        let Stacked { hist: hist_idx, targets: target_idx, anchors, act } = stack(&windows, n, device);
        for idx in [&hist_idx, &target_idx, &anchors] {
            self.latents.ensure(idx, codec, inner);
        }
        let latents = &*self.latents;
        let hist = latents.tensor(&hist_idx, k, device).swap_dims(1, 2); // [b n, C, K, s, s]
        // Context noise corrupts the history only: the anchor is always a real frame.
        let hist = crate::context_noise::corrupt(hist, cfg.context_noise, derive(cfg.seed, &[step, 7]));
        let anchor = model_cfg.unet.uses_anchor().then(|| anchor_tensor(latents, &anchors, device)); // [b n, C, s, s]
        let targets = Targets { latents, windows: &windows, indices: &target_idx, chunks };
        let (loss, loss_r) = objective_loss(&unet, (model_cfg, cfg), (hist, anchor, act), &targets, &mut rng);
        let loss_value: f64 = loss.clone().into_scalar::<f32>().into();
        finite(loss_value, || format!("{} loss", objective.name()), (step, self.out))?;
        let mut grads = GradientsParams::from_grads(loss.backward(), &unet);
        let grad_norm = clip_global_norm(&unet, &mut grads, cfg.clip_norm);
        finite(grad_norm, || "gradient norm".into(), (step, self.out))?;
        let lr = warmup_lr(step, cfg.lr, cfg.warmup);
        let unet = optim.step(lr, unet, grads);
        self.ema.update(&unet);
        self.state.step += 1;
        self.state.elapsed_s = elapsed_s();
        if self.state.step.is_multiple_of(cfg.eval_every) || self.state.step == cfg.steps {
            let mse = self.held_out_mse();
            finite(mse, || "generated frames".into(), (step, self.out))?;
            self.last.2 = Some(mse);
            tracing::info!(
                step = self.state.step,
                loss = loss_value,
                eval_mse = mse,
                "world-model held-out eval"
            );
        }
        let line = json!({"step": self.state.step, "loss": loss_value, "loss_r": loss_r, "grad_norm": grad_norm,
            "lr": lr, "eval_mse": self.last.2, "elapsed_s": self.state.elapsed_s});
        (self.last.0, self.last.1) = (loss_value, loss_r);
        Ok(((unet, optim), Some(line)))
    }

    fn checkpoint_due(&self) -> bool {
        self.state.step.is_multiple_of(self.configs.1.checkpoint_every)
    }

    fn save(&mut self, (unet, optim): &Self::Net, _elapsed_s: f64) -> Result<(), WorldModelError> {
        save_checkpoint(self.out, (unet, &self.ema.module, optim), &self.state)
    }

    fn progress(&mut self) {
        (self.on_progress)(&WmProgress {
            step: self.state.step,
            total: self.configs.1.steps,
            loss: self.last.0,
            loss_r: self.last.1.clone(),
            eval_mse: self.last.2,
        });
    }
}

/// Trains (or resumes) into `out` on `device` (see [`nn::device`]). The codec of
/// `frames` must be the one `model_cfg` names (the autoencoder at
/// `out/model.autoencoder`, or pixels), loaded on the same device.
///
/// # Errors
/// [`WorldModelError`] for unreadable checkpoints, I/O failures or a non-finite loss
/// (naming the step).
pub fn train_world_model(
    frames: TrainingFrames,
    out: &Path,
    model_cfg: &WorldModelConfig,
    cfg: &WmTrainConfig,
    run: RunOptions,
    device: &Device,
    on_progress: &mut dyn FnMut(&WmProgress),
) -> Result<WmOutcome, WorldModelError> {
    let TrainingFrames { data, codec } = frames;
    let (inner, device) = (device.clone(), device.clone().autodiff());
    let fresh = Configs { model: model_cfg.clone(), train: cfg.clone() };
    let (model_cfg, cfg) = run_configs(out, fresh, run, |t: &mut WmTrainConfig| &mut t.steps)?;
    let objective = model_cfg.objective;
    // Training windows hold every chunk of a self-forcing rollout; evaluation windows one.
    let chunks = if objective == Objective::Drifting { cfg.chunks.max(1) } else { 1 };
    let (starts, eval_windows, scale) = windows_of(data, &model_cfg, &cfg, chunks)?;
    let mut latents = Latents::new(data, model_cfg.latents.clone(), codec);
    // The fresh weights are a function of the seed (a run's bytes follow from its command).
    device.seed(derive(cfg.seed, &[u64::MAX - 1]));
    let mut unet: UNet = model_cfg.unet.init(&device);
    let mut optim = AdamWConfig::new().with_beta_1(0.9).with_beta_2(0.95).with_weight_decay(0.01).init();
    let mut ema = Ema::new(&unet, cfg.ema_decay);
    let mut state = State { step: 0, elapsed_s: 0.0 };
    if let Some(dir) = cfg.init_from.as_ref().filter(|_| !run.resume) {
        unet = warm_start(dir, &model_cfg, &device)?;
        ema.module = unet.valid(); // the same draw of any new (zero-output) layers
    }
    if run.resume {
        (unet, ema.module, optim, state) = resume(out, (unet, model_cfg.unet.init(&inner), optim))?;
    }
    // Noise continues from a seed of (seed, step), so a resumed run draws fresh noise.
    device.seed(derive(cfg.seed, &[u64::MAX, state.step]));
    let log = out.join("train_log.jsonl");
    let mut driver = Driver::start(&log, "step", state.step, state.elapsed_s, Clock::start(run.max_minutes))?;
    let mut steps = WmSteps {
        frames: TrainingFrames { data, codec },
        configs: (&model_cfg, &cfg),
        out,
        devices: (&device, &inner),
        windows: (&starts, &eval_windows, &scale),
        latents: &mut latents,
        ema: &mut ema,
        state,
        last: (f64::NAN, Vec::new(), None),
        on_progress,
    };
    driver.train(&mut steps, (unet, optim))?;
    let eval_mse = steps.held_out_mse();
    let state = steps.state;
    Ok(WmOutcome {
        step: state.step,
        total: cfg.steps,
        finished: state.step >= cfg.steps,
        eval_mse,
        elapsed_s: state.elapsed_s,
    })
}
