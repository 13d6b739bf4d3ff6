//! Training a diffusion policy, saving a policy checkpoint every few epochs.
//!
//! The checkpoints along one run form a graded policy set: early epochs act
//! poorly, later ones well — what `rank` needs to measure agreement on.
//!
//! Output folder:
//! - `epoch-NNNN/`: a loadable policy checkpoint (`policy.json` + `model.bpk`);
//! - `.train/`: the resumable training state (`config.json`, `model.bpk`,
//!   `ema.bpk`, `optimizer.bpk`, `state.json`, `log.jsonl`); hidden so that policy
//!   loaders skip it.
//!
//! An epoch is one pass over every sample in a permutation that is a function of
//! (seed, epoch), so a resumed run visits exactly the samples an uninterrupted one would.

use std::path::{Path, PathBuf};

use burn::optim::GradientsParams;
use burn::tensor::Device;
use harness::driver::{Clock, Driver};
use harness::rng::Rng;
use harness::seed::derive;
use serde_json::json;

use crate::data::Demos;
use crate::diffusion::alphas_cumprod;
use crate::dir::PolicyLoadError;
use crate::provenance::PolicyProvenance;
pub use crate::train_config::{
    Phase, PolicyOutcome, PolicyProgress, PolicyRun, PolicyTrainConfig, RunConfigs,
};
use crate::train_parts::{Features, Training, batch_loss, features, save_epoch};

/// Trains (or resumes) a diffusion policy into `out` on `inner` (its autodiff
/// wrapper for the gradients; see `nn::device`).
///
/// # Errors
/// [`PolicyLoadError`] naming the file for unreadable state or I/O failures, or a
/// non-finite loss (naming the step).
pub fn train_policy(
    demos: &Demos,
    out: &Path,
    configs: &RunConfigs,
    run: PolicyRun,
    inner: &Device,
    on_progress: &mut dyn FnMut(&PolicyProgress),
) -> Result<PolicyOutcome, PolicyLoadError> {
    let dir = out.join(".train");
    let cfg_path = dir.join("config.json");
    // This session's command, recorded when resuming (the saved provenance holds the first).
    let session_command = configs.provenance.command.clone();
    let configs =
        harness::runfile::resume_or_start(&cfg_path, configs.clone(), run.resume, |c: &mut RunConfigs| {
            let extend = run.epochs.filter(|&e| e != c.train.epochs);
            c.train.epochs = extend.unwrap_or(c.train.epochs);
            let ema = run.ema.filter(|&d| d != c.train.ema);
            c.train.ema = ema.unwrap_or(c.train.ema);
            extend.is_some() || ema.is_some()
        })?;
    let (pc, tc) = (&configs.policy, &configs.train);
    let device = inner.clone().autodiff();
    let (pd, ad) = (demos.proprio_dim, demos.action_dim);
    if (pc.net.proprio(), pc.net.action_dim) != (pd, ad) {
        return Err(PolicyLoadError::new(
            out,
            format!(
                "the policy takes {}-entry proprioception and {}-entry actions, the demonstrations have {pd} and {ad}",
                pc.net.proprio(),
                pc.net.action_dim
            ),
        ));
    }
    let n = demos.len();
    let per_epoch = n.div_ceil(tc.batch.max(1)) as u64;
    let total = per_epoch * tc.epochs;
    let mut tr = Training::start(&dir, &configs, &run, &device)?;
    // One clock for both stages: `--max-minutes` bounds the session, pre-training included.
    let clock = Clock::start(run.max_minutes);
    let mut provenance = configs.provenance.clone();
    if run.resume {
        provenance.resumed_with = Some(session_command);
    }
    let features = features(demos, &configs, &mut tr, &mut provenance, (&dir, clock), inner, on_progress)?;
    if let Features::Stopped = features {
        // Stopped during pre-training: the run's own state is what `--resume` looks for.
        tr.save(&dir)?;
        let (step, elapsed_s) = (tr.state.step, tr.state.elapsed_s);
        return Ok(PolicyOutcome { step, total, saved: Vec::new(), loss: f64::NAN, elapsed_s });
    }
    let ac = alphas_cumprod(pc.train_steps);
    let mut driver = Driver::start(&dir.join("log.jsonl"), "step", tr.state.step, tr.state.elapsed_s, clock)?;
    let step = tr.state.step;
    let mut steps = PolicySteps {
        demos,
        configs: &configs,
        provenance: &provenance,
        paths: (out, &dir),
        device: &device,
        features: &features,
        ac: &ac,
        sizes: (n, per_epoch, total),
        order: (u64::MAX, Vec::new()),
        step,
        last: (0, f64::NAN),
        recent: Vec::new(),
        saved: Vec::new(),
        on_progress,
    };
    let (tr, _) = driver.train(&mut steps, tr)?;
    let loss = steps.recent.iter().sum::<f64>() / steps.recent.len().max(1) as f64;
    Ok(PolicyOutcome { step: tr.state.step, total, saved: steps.saved, loss, elapsed_s: tr.state.elapsed_s })
}

/// The policy's steps for the shared loop ([`Driver::train`]): a batch in the epoch's
/// permutation, the denoising loss, an AdamW step, the EMA; a policy checkpoint
/// (`epoch-NNNN/`) at every `save_every`-th epoch's end and the last, and the resumable state
/// every `checkpoint_every` steps and at every epoch's end.
struct PolicySteps<'a> {
    demos: &'a Demos,
    configs: &'a RunConfigs,
    provenance: &'a PolicyProvenance,
    /// The run's folder and its `.train/`.
    paths: (&'a Path, &'a Path),
    device: &'a Device,
    features: &'a Features,
    /// The noise schedule's ᾱ.
    ac: &'a [f64],
    /// Samples, steps per epoch, steps in all.
    sizes: (usize, u64, u64),
    /// The epoch whose permutation is held, and the permutation.
    order: (u64, Vec<usize>),
    /// Steps done (the training state's, which moves through the loop with the network).
    step: u64,
    /// The last step's epoch (from 1) and loss.
    last: (u64, f64),
    /// The last 50 losses.
    recent: Vec<f64>,
    /// The policy checkpoints written.
    saved: Vec<PathBuf>,
    on_progress: &'a mut dyn FnMut(&PolicyProgress),
}

impl harness::driver::Steps for PolicySteps<'_> {
    type Net = Training;
    type Line = serde_json::Value;
    type Error = PolicyLoadError;

    fn done(&self) -> u64 {
        self.step
    }

    fn total(&self) -> u64 {
        self.sizes.2
    }

    fn step(&mut self, mut tr: Training, elapsed_s: &dyn Fn() -> f64) -> harness::driver::Stepped<Self> {
        let ((n, per_epoch, _), tc) = (self.sizes, &self.configs.train);
        let epoch = tr.state.step / per_epoch;
        if self.order.0 != epoch {
            self.order = (epoch, permutation(n, derive(tc.seed, &[epoch])));
        }
        let k = (tr.state.step % per_epoch) as usize * tc.batch;
        let batch = &self.order.1[k..(k + tc.batch).min(n)];
        let loss = batch_loss(
            &tr.net,
            self.demos,
            self.configs,
            (batch, tr.state.step),
            self.features,
            self.ac,
            self.device,
        );
        let lv: f64 = loss.clone().into_scalar::<f32>().into();
        if !lv.is_finite() {
            return Err(PolicyLoadError::new(
                self.paths.0,
                format!("non-finite loss at training step {}", tr.state.step),
            ));
        }
        let grads = GradientsParams::from_grads(loss.backward(), &tr.net);
        tr.net = tr.optim.step(lr_at(tr.state.step, tc), tr.net, grads);
        tr.state.step += 1;
        if tc.ema > 0.0 {
            let k = tr.state.ema_updates as f64;
            tr.ema.decay = tc.ema.min((1.0 + k) / (10.0 + k));
            tr.ema.update(&tr.net);
            tr.state.ema_updates += 1;
        }
        tr.state.elapsed_s = elapsed_s();
        self.recent.push(lv);
        if self.recent.len() > 50 {
            self.recent.remove(0);
        }
        (self.step, self.last) = (tr.state.step, (epoch + 1, lv));
        let line =
            json!({"step": tr.state.step, "epoch": epoch + 1, "loss": lv, "elapsed_s": tr.state.elapsed_s});
        Ok((tr, Some(line)))
    }

    fn checkpoint_due(&self) -> bool {
        let (tc, per_epoch) = (&self.configs.train, self.sizes.1);
        self.step.is_multiple_of(tc.checkpoint_every) || self.step.is_multiple_of(per_epoch)
    }

    /// At a save-worthy epoch's end, its policy checkpoint first (once), then the state.
    fn save(&mut self, tr: &Training, _elapsed_s: f64) -> Result<(), PolicyLoadError> {
        let (tc, per_epoch) = (&self.configs.train, self.sizes.1);
        let done = self.step / per_epoch;
        let epoch_end = self.step.is_multiple_of(per_epoch) && self.step > 0;
        let wanted = done.is_multiple_of(tc.save_every) || done == tc.epochs;
        let ck = self.paths.0.join(format!("epoch-{done:04}"));
        if epoch_end && wanted && self.last.0 == done && !self.saved.contains(&ck) {
            self.saved.push(save_epoch(
                self.paths.0,
                self.configs,
                self.provenance,
                tr,
                (done, self.last.1),
            )?);
        }
        tr.save(self.paths.1)
    }

    fn progress(&mut self) {
        let (step, total) = (self.step, self.sizes.2);
        let (epoch, loss) = self.last;
        (self.on_progress)(&PolicyProgress { phase: Phase::Policy, step, total, epoch, loss });
    }
}

/// Linear warm-up, then constant.
fn lr_at(step: u64, tc: &PolicyTrainConfig) -> f64 {
    if step < tc.warmup { tc.lr * (step + 1) as f64 / tc.warmup as f64 } else { tc.lr }
}

/// A Fisher–Yates permutation of 0..n from a seed.
fn permutation(n: usize, seed: u64) -> Vec<usize> {
    let mut rng = Rng::new(seed);
    let mut p: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        p.swap(i, rng.below(i as u64 + 1) as usize);
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn permutation_is_a_permutation_and_seeded() {
        let mut p = permutation(50, 3);
        assert_eq!(p, permutation(50, 3));
        assert_ne!(p, permutation(50, 4));
        p.sort_unstable();
        assert_eq!(p, (0..50).collect::<Vec<_>>());
    }
}
