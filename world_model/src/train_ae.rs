//! Training the frame autoencoder: resumable, time-boxed, evaluated on held-out episodes.
//!
//! Output folder:
//! - `config.json`: model and training configs (written first; reloaded on `--resume`);
//! - `model.bpk`, `optimizer.bpk`, `state.json`: the latest checkpoint (step, elapsed time);
//! - `train_log.jsonl`: one line per logged step (loss, learning rate, held-out PSNR).
//!
//! Batches are a pure function of (seed, step), so a resumed run draws exactly the
//! batches an uninterrupted one would have.

use std::path::Path;

use burn::module::Module;
use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::Device;
use harness::driver::{Clock, Driver};
use harness::seed::derive;
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::autoencoder::{Autoencoder, AutoencoderConfig};
use crate::data::{EpisodeData, Split, psnr};
use crate::error::WorldModelError;
use nn::frames::tensor_to_frames;

/// Training hyper-parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AeTrainConfig {
    /// Optimizer steps in total.
    pub steps: u64,
    /// Frames per step.
    pub batch: usize,
    /// Peak learning rate (AdamW, β = (0.9, 0.95), weight decay 0.01).
    pub lr: f64,
    /// Linear warm-up steps from 1e-6 to `lr`, then constant.
    pub warmup: u64,
    /// Seed of the initial weights and the batches.
    pub seed: u64,
    /// Held-out evaluation every this many steps.
    pub eval_every: u64,
    /// Held-out frames used for the evaluation (evenly spaced over the split).
    pub eval_frames: usize,
    /// Checkpoint every this many steps.
    pub checkpoint_every: u64,
    /// Train only the decoder: the encoder's weights come from this autoencoder and
    /// stay fixed, so the latents (and world models trained on them) are unchanged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub encoder_from: Option<std::path::PathBuf>,
}

impl Default for AeTrainConfig {
    fn default() -> Self {
        Self {
            steps: 4000,
            batch: 16,
            lr: 1e-3,
            warmup: 200,
            seed: 0,
            eval_every: 250,
            eval_frames: 256,
            checkpoint_every: 100,
            encoder_from: None,
        }
    }
}

/// How to run a training session.
#[derive(Clone, Copy, Debug, Default)]
pub struct RunOptions {
    /// Continue the run in the output folder from its checkpoint.
    pub resume: bool,
    /// When resuming, replace the saved total steps with `cfg.steps`.
    pub extend: bool,
    /// Stop (with a checkpoint) after this many minutes.
    pub max_minutes: Option<f64>,
}

/// A training progress report.
#[derive(Clone, Debug)]
pub struct AeProgress {
    /// Steps done.
    pub step: u64,
    /// Steps in total.
    pub total: u64,
    /// Last batch loss (MSE on [-1, 1] pixels).
    pub loss: f64,
    /// Last held-out PSNR (dB), if evaluated.
    pub psnr: Option<f64>,
}

/// What a (possibly time-limited) run ended with.
#[derive(Clone, Debug)]
pub struct AeOutcome {
    /// Steps done in total.
    pub step: u64,
    /// Steps configured in total.
    pub total: u64,
    /// Whether all configured steps are done.
    pub finished: bool,
    /// Held-out PSNR (dB) and MSE at the end.
    pub psnr: f64,
    /// Held-out MSE on [-1, 1] pixels.
    pub mse: f64,
    /// A few held-out frames and their reconstructions (HWC bytes).
    pub samples: Vec<SamplePair>,
    /// Wall seconds over all sessions.
    pub elapsed_s: f64,
}

/// A held-out frame and its reconstruction (HWC bytes).
pub type SamplePair = (Vec<u8>, Vec<u8>);

pub(crate) use harness::driver::State;

/// What a trainer's `config.json` holds: the model's and the training's configs.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Configs<M, T> {
    /// The model's.
    pub model: M,
    /// The training's.
    pub train: T,
}

/// An autoencoder run's `config.json`.
pub type AeConfigs = Configs<AutoencoderConfig, AeTrainConfig>;

/// The configs of a run in `out`: written fresh, or read back when resuming (the
/// saved ones win), with the step total (`steps` picks it) replaced when extending.
pub(crate) fn run_configs<M, T>(
    out: &Path,
    mut fresh: Configs<M, T>,
    run: RunOptions,
    steps: fn(&mut T) -> &mut u64,
) -> Result<(M, T), WorldModelError>
where
    M: Serialize + serde::de::DeserializeOwned,
    T: Serialize + serde::de::DeserializeOwned,
{
    let want = *steps(&mut fresh.train);
    let c = harness::runfile::resume_or_start(&out.join("config.json"), fresh, run.resume, |c| {
        let changed = run.extend && *steps(&mut c.train) != want;
        if changed {
            *steps(&mut c.train) = want;
        }
        changed
    })?;
    Ok((c.model, c.train))
}

pub(crate) fn ckpt(path: &Path, e: impl std::fmt::Display) -> WorldModelError {
    WorldModelError::Checkpoint { path: path.to_path_buf(), message: e.to_string() }
}

/// Reads a run's `config.json` as `C` ([`AeConfigs`], [`crate::train_wm::WmConfigs`]).
///
/// # Errors
/// [`WorldModelError::Checkpoint`] naming the file when it is missing or malformed.
pub fn read_configs<C: serde::de::DeserializeOwned>(path: &Path) -> Result<C, WorldModelError> {
    harness::runfile::read(path).map_err(WorldModelError::from)
}

/// Loads a trained autoencoder from its folder (`config.json` + `model.bpk`).
///
/// # Errors
/// [`WorldModelError::Checkpoint`] naming the file when it is missing, unreadable or
/// does not match its config.
pub fn load_autoencoder(
    dir: &Path,
    device: &Device,
) -> Result<(Autoencoder, AutoencoderConfig), WorldModelError> {
    let cfg_path = dir.join("config.json");
    let cfgs: AeConfigs = read_configs(&cfg_path)?;
    let weights = dir.join("model.bpk");
    let model = cfgs.model.init(device).try_load_file(&weights).map_err(|e| ckpt(&weights, e))?;
    Ok((model, cfgs.model))
}

/// Held-out PSNR/MSE of `model` on `idx`, in chunks of 32 frames.
fn evaluate(
    model: &Autoencoder,
    data: &EpisodeData,
    idx: &[usize],
    device: &Device,
) -> (f64, f64, Vec<SamplePair>) {
    let model = model.valid();
    let (mut psnr_sum, mut mse_sum, mut samples) = (0.0, 0.0, Vec::new());
    // Eight sample pairs spread over the evaluation frames (different episodes).
    let every = (idx.len() / 8).max(1);
    let mut k = 0;
    for chunk in idx.chunks(32) {
        let x = data.frames_tensor(chunk, device);
        let y = model.forward(x.clone());
        let mse: f64 = (y.clone() - x.clone()).powf_scalar(2.0).mean().into_scalar::<f32>().into();
        mse_sum += mse * chunk.len() as f64;
        for (orig, rec) in tensor_to_frames(x).into_iter().zip(tensor_to_frames(y)) {
            psnr_sum += psnr(&orig, &rec).min(100.0);
            if k % every == 0 && samples.len() < 8 {
                samples.push((orig, rec));
            }
            k += 1;
        }
    }
    let n = idx.len().max(1) as f64;
    (psnr_sum / n, mse_sum / n, samples)
}

/// Trains (or resumes training) into `out` on `device`; stops at the configured steps or after
/// `max_minutes`, whichever comes first, with a checkpoint either way. When
/// resuming, the saved configs win, except that `cfg.steps` replaces the saved
/// total if `extend` is set (to continue a finished run further).
///
/// # Errors
/// [`WorldModelError`] for unreadable checkpoints, I/O failures, or a non-finite loss
/// (naming the step).
pub fn train_autoencoder(
    data: &EpisodeData,
    out: &Path,
    model_cfg: &AutoencoderConfig,
    cfg: &AeTrainConfig,
    run: RunOptions,
    device: &Device,
    on_progress: &mut dyn FnMut(&AeProgress),
) -> Result<AeOutcome, WorldModelError> {
    let RunOptions { resume, max_minutes, .. } = run;
    let device = device.clone().autodiff();
    device.seed(cfg.seed);
    let fresh = Configs { model: model_cfg.clone(), train: cfg.clone() };
    let (model_cfg, cfg) = run_configs(out, fresh, run, |t: &mut AeTrainConfig| &mut t.steps)?;
    let mut model = model_cfg.init(&device);
    if let (Some(dir), false) = (&cfg.encoder_from, resume) {
        let (source, source_cfg) = load_autoencoder(dir, &device)?;
        if !model_cfg.same_encoder(&source_cfg) {
            return Err(ckpt(
                &dir.join("config.json"),
                "its encoder (image size, channels, latent channels, groups) differs from this run's",
            ));
        }
        model = model.with_encoder_of(source);
    }
    let mut optim = AdamWConfig::new().with_beta_1(0.9).with_beta_2(0.95).with_weight_decay(0.01).init();
    let mut state = State { step: 0, elapsed_s: 0.0 };
    if resume {
        (model, optim, state) = resume_from(out, model, optim)?;
    }
    let train_idx = data.frame_indices(Split::Train);
    let held = data.frame_indices(Split::HeldOut);
    if train_idx.is_empty() || held.is_empty() {
        return Err(WorldModelError::Data {
            path: data.source.clone(),
            message: format!("{} episodes: need at least 10 (every 10th is held out)", data.episodes.len()),
        });
    }
    let stride = (held.len() / cfg.eval_frames.max(1)).max(1);
    let eval_idx: Vec<usize> = held.iter().step_by(stride).take(cfg.eval_frames).copied().collect();
    let clock = Clock::start(max_minutes);
    let mut driver = Driver::start(&out.join("train_log.jsonl"), "step", state.step, state.elapsed_s, clock)?;
    let mut steps = AeSteps {
        data,
        cfg: &cfg,
        out,
        device: &device,
        sets: (&train_idx, &eval_idx),
        state,
        last: (f64::NAN, None),
        on_progress,
    };
    let (model, _) = driver.train(&mut steps, (model, optim))?.0;
    let state = steps.state;
    let (psnr_v, mse, samples) = evaluate(&model, data, &eval_idx, &device);
    Ok(AeOutcome {
        step: state.step,
        total: cfg.steps,
        finished: state.step >= cfg.steps,
        psnr: psnr_v,
        mse,
        samples,
        elapsed_s: state.elapsed_s,
    })
}

/// A resumed run's checkpoint in `out`, recovered first if a save was cut short: the weights
/// (loaded into `model`), the optimiser and the state.
///
/// # Errors
/// An unreadable checkpoint file, naming it.
fn resume_from(
    out: &Path,
    model: Autoencoder,
    optim: burn::optim::ModuleOptimizer,
) -> Result<(Autoencoder, burn::optim::ModuleOptimizer, State), WorldModelError> {
    let (model_path, optim_path, state_path) =
        (out.join("model.bpk"), out.join("optimizer.bpk"), out.join("state.json"));
    harness::checkpoint::recover(out, harness::checkpoint::MAIN)?;
    let model = model.try_load_file(&model_path).map_err(|e| ckpt(&model_path, e))?;
    let optim = optim.load(&optim_path).map_err(|e| ckpt(&optim_path, e))?;
    let state = harness::driver::read_state(&state_path)?;
    Ok((model, optim, state))
}

/// The autoencoder's steps for the shared loop ([`Driver::train`]): a batch of training
/// frames reconstructed, the held-out PSNR every `eval_every` steps, a checkpoint every
/// `checkpoint_every`.
struct AeSteps<'a> {
    data: &'a EpisodeData,
    cfg: &'a AeTrainConfig,
    out: &'a Path,
    device: &'a Device,
    /// The training frames, and the held-out ones evaluated.
    sets: (&'a [usize], &'a [usize]),
    state: State,
    /// The last batch loss and held-out PSNR.
    last: (f64, Option<f64>),
    on_progress: &'a mut dyn FnMut(&AeProgress),
}

impl harness::driver::Steps for AeSteps<'_> {
    type Net = (Autoencoder, burn::optim::ModuleOptimizer);
    type Line = serde_json::Value;
    type Error = WorldModelError;

    fn done(&self) -> u64 {
        self.state.step
    }

    fn total(&self) -> u64 {
        self.cfg.steps
    }

    fn step(
        &mut self,
        (model, mut optim): Self::Net,
        elapsed_s: &dyn Fn() -> f64,
    ) -> harness::driver::Stepped<Self> {
        let (cfg, step) = (self.cfg, self.state.step);
        let (train_idx, eval_idx) = self.sets;
        let mut rng = derive(cfg.seed, &[step]);
        let idx: Vec<usize> = (0..cfg.batch)
            .map(|_| {
                rng = harness::seed::splitmix64(rng);
                train_idx[(rng % train_idx.len() as u64) as usize]
            })
            .collect();
        let lr = nn::optim::warmup_lr(step, cfg.lr, cfg.warmup);
        let x = self.data.frames_tensor(&idx, self.device);
        let recon = match cfg.encoder_from {
            // A fixed encoder: it encodes on the inner backend, so no gradient reaches it
            // and the optimizer leaves it as loaded. (Encoding on the autodiff device and
            // detaching leaks: backward never frees the detached part of the graph.)
            Some(_) => model.decode(model.valid().encode(x.clone().inner()).autodiff()), // z: [b, C, 12, 12]
            None => model.forward(x.clone()),
        }; // [b, 3, 96, 96]
        let loss = (recon - x).powf_scalar(2.0).mean();
        let loss_value: f64 = loss.clone().into_scalar::<f32>().into();
        finite(loss_value, || "autoencoder loss".into(), (step, self.out))?;
        let grads = GradientsParams::from_grads(loss.backward(), &model);
        let model = optim.step(lr, model, grads);
        self.state.step += 1;
        self.state.elapsed_s = elapsed_s();
        if self.state.step.is_multiple_of(cfg.eval_every) || self.state.step == cfg.steps {
            let (p, mse, _) = evaluate(&model, self.data, eval_idx, self.device);
            self.last.1 = Some(p);
            tracing::info!(
                step = self.state.step,
                loss = loss_value,
                psnr = p,
                mse,
                "autoencoder held-out eval"
            );
        }
        self.last.0 = loss_value;
        let line = json!({"step": self.state.step, "loss": loss_value, "lr": lr, "psnr": self.last.1, "elapsed_s": self.state.elapsed_s});
        Ok(((model, optim), Some(line)))
    }

    fn checkpoint_due(&self) -> bool {
        self.state.step.is_multiple_of(self.cfg.checkpoint_every)
    }

    fn save(&mut self, (model, optim): &Self::Net, _elapsed_s: f64) -> Result<(), WorldModelError> {
        save_checkpoint(self.out, model, optim, &self.state)
    }

    fn progress(&mut self) {
        let (loss, psnr) = self.last;
        (self.on_progress)(&AeProgress { step: self.state.step, total: self.cfg.steps, loss, psnr });
    }
}

/// Writes the weights, the optimiser and `state` as one checkpoint of `out`: staged, then
/// committed by a manifest.
///
/// # Errors
/// A file that cannot be written, naming it.
fn save_checkpoint(
    out: &Path,
    model: &Autoencoder,
    optim: &burn::optim::ModuleOptimizer,
    state: &State,
) -> Result<(), WorldModelError> {
    let mut stage = harness::checkpoint::begin(out, harness::checkpoint::MAIN)?;
    let p = ["model.bpk", "optimizer.bpk", "state.json"].map(|n| stage.path(n));
    model.clone().save_file(&p[0]).map_err(|e| ckpt(&p[0], e))?;
    optim.save(&p[1]).map_err(|e| ckpt(&p[1], e))?;
    harness::driver::write_state(&p[2], state)?;
    Ok(stage.commit()?)
}

/// `Err` naming `what` at `step` of the run in `out` unless `value` is finite.
pub(crate) fn finite(
    value: f64,
    what: impl FnOnce() -> String,
    (step, out): (u64, &Path),
) -> Result<(), WorldModelError> {
    if value.is_finite() {
        return Ok(());
    }
    Err(WorldModelError::NonFinite { what: what(), step, path: out.to_path_buf() })
}
