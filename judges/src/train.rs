//! Training a learned judge ([`crate::folder`]) on simulator frames labelled with the
//! exact score: Push-T's `data/coverage`, robomimic's `data/success`.
//!
//! Every 10th episode (index % 10 == 9) is held out; the judge's reading of those
//! frames ([`JudgeMetrics`]: mean absolute error, accuracy, recall and precision at
//! the success threshold) is logged while training and stored in `judge.json`. The
//! last evaluation also reads each held-out episode whole, as `rank` reads an
//! imagined one ([`EpisodeReading`], [`crate::read`]: the frames the policy
//! sees, `persist_frames` in a row): a judge may misplace the frame where success
//! begins and still call every episode right, or the reverse.
//! Successes are rare in most datasets (a frame above coverage 0.95, a lifted
//! cube), so by default half of each batch is drawn from the frames above the
//! threshold. The loss is binary cross-entropy against the label, which for
//! coverage is a soft target in [0, 1]. Push-T frames can be augmented with the 8
//! symmetries of the square world ([`augment_frame`]): coverage is invariant under
//! them, since block and goal move together.
//!
//! A run resumes as the other trainers' do ([`crate::run`]: its `.train` folder): a
//! session that reaches its time limit (`--max-minutes`) or is stopped (Ctrl-C) saves its
//! checkpoint, and the judge trained so far is evaluated and written with the steps it
//! took; `--resume` goes on from there to the same weights an uninterrupted run ends with.

use std::path::Path;

use burn::module::Module;
use burn::optim::{AdamWConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};
use harness::driver::{Clock, Driver};
use harness::rng::Rng;
use harness::seed::derive;
use serde::Serialize;

use nn::frames::frames_to_tensor;
use policies::symmetry::augment_frame;

use crate::error::JudgeError;
use crate::folder::{FrameJudge, JudgeFile, JudgeNet};
use crate::metrics::{EpisodeReading, JudgeMetrics, Reading, metrics};
pub use crate::provenance::JudgeTrainConfig;
use crate::read::{JudgeData, judge_episodes, read_judged};
use crate::run::{self, State};

/// Linear warm-up steps of the learning rate.
const WARMUP: u64 = 100;
/// Held-out frames evaluated at most (evenly spaced).
const EVAL_FRAMES: usize = 2048;

/// A line of the judge's training log (`log.jsonl`); fields in alphabetical order, the
/// order the lines had as sorted JSON maps.
#[derive(Serialize)]
struct LogLine {
    /// The held-out metrics.
    heldout: JudgeMetrics,
    /// The step's loss.
    loss: f64,
    /// The last line of a run `--max-minutes` stopped early.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    out_of_time: bool,
    /// Steps done.
    step: u64,
}

/// Mean binary cross-entropy of `logits` against soft `targets` in [0, 1]:
/// max(z, 0) − y·z + log(1 + e^−|z|), stable for any logit.
///
/// # Shapes
/// `logits, targets: [n, 1]` → `[1]`
pub fn bce_with_logits(logits: Tensor<2>, targets: Tensor<2>) -> Tensor<1> {
    let softplus_neg_abs = logits.clone().abs().neg().exp().add_scalar(1.0).log();
    (relu(logits.clone()) - targets * logits + softplus_neg_abs).mean()
}

/// The judge's reading of `steps` (up to [`EVAL_FRAMES`], evenly spaced).
pub fn evaluate(judge: &FrameJudge, data: &JudgeData, steps: &[usize], threshold: f64) -> JudgeMetrics {
    let pick: Vec<usize> = if steps.len() <= EVAL_FRAMES {
        steps.to_vec()
    } else {
        (0..EVAL_FRAMES).map(|k| steps[k * steps.len() / EVAL_FRAMES]).collect()
    };
    let mut est = Vec::with_capacity(pick.len());
    for part in pick.chunks(64) {
        let frames: Vec<&[u8]> = part.iter().map(|&i| data.frame(i)).collect();
        est.extend(judge.score_frames(&frames));
    }
    metrics(&est, &pick.iter().map(|&i| f64::from(data.labels[i])).collect::<Vec<_>>(), threshold)
}

/// One session of a judge run: its `.train` folder ([`crate::run`]), whether it continues
/// the run saved there, and its clock (`--max-minutes`).
pub struct JudgeSession<'a> {
    /// The run's `.train` folder.
    pub dir: &'a Path,
    /// Continue the run saved in `dir`.
    pub resume: bool,
    /// The session's start and deadline.
    pub clock: Clock,
}

/// What a session ended with.
pub struct JudgeOutcome {
    /// The judge (inference device) and its held-out metrics; `None` before the run's
    /// first step.
    pub judge: Option<(JudgeNet, JudgeMetrics)>,
    /// Steps done.
    pub step: u64,
    /// Training seconds over all sessions.
    pub elapsed_s: f64,
}

/// The judge's steps for the shared loop ([`Driver::train`]): a batch of training frames
/// (every other one a positive when `balance`, each through a random symmetry when
/// `symmetries`), binary cross-entropy, an AdamW step after a linear warm-up; the held-out
/// metrics logged and a checkpoint saved every `eval_every` steps before the last.
struct JudgeSteps<'a> {
    data: &'a JudgeData,
    cfg: &'a JudgeTrainConfig,
    judge: &'a JudgeFile,
    /// The training frames, the positives among them, the held-out frames.
    sets: (&'a [usize], &'a [usize], &'a [usize]),
    /// The autodiff device training runs on, and the inference one.
    devices: (&'a Device, &'a Device),
    dir: &'a Path,
    state: State,
    /// The last batch's loss.
    loss: f64,
    on_step: &'a mut dyn FnMut(u64, f64),
    dataset: &'a Path,
}

impl harness::driver::Steps for JudgeSteps<'_> {
    type Net = (JudgeNet, ModuleOptimizer);
    type Line = LogLine;
    type Error = JudgeError;

    fn done(&self) -> u64 {
        self.state.step
    }

    fn total(&self) -> u64 {
        self.cfg.steps
    }

    fn step(
        &mut self,
        (net, mut optim): Self::Net,
        _elapsed_s: &dyn Fn() -> f64,
    ) -> harness::driver::Stepped<Self> {
        let (cfg, data, step) = (self.cfg, self.data, self.state.step);
        let ((train, positives, held), (device, inner)) = (self.sets, self.devices);
        let mut rng = Rng::new(derive(cfg.seed, &[step]));
        let idx: Vec<(usize, u8)> = (0..cfg.batch)
            .map(|j| {
                let pool = if cfg.balance && !positives.is_empty() && j % 2 == 1 { positives } else { train };
                let k = if cfg.symmetries { rng.below(8) as u8 } else { 0 };
                (pool[rng.below(pool.len() as u64) as usize], k)
            })
            .collect();
        let s = data.size;
        let owned: Vec<Vec<u8>> = idx.iter().map(|&(i, k)| augment_frame(data.frame(i), s, k)).collect();
        let frames: Vec<&[u8]> = owned.iter().map(Vec::as_slice).collect();
        let y: Vec<f32> = idx.iter().map(|&(i, _)| data.labels[i].clamp(0.0, 1.0)).collect();
        let y = Tensor::from_data(TensorData::new(y, [cfg.batch, 1]), device);
        let loss = bce_with_logits(net.forward(frames_to_tensor(&frames, s, device)), y);
        let lv: f64 = loss.clone().into_scalar::<f32>().into();
        if !lv.is_finite() {
            let what = format!("non-finite judge loss at step {step}");
            return Err(JudgeError::Dataset { path: self.dataset.into(), what });
        }
        let grads = GradientsParams::from_grads(loss.backward(), &net);
        let lr = cfg.lr * ((step + 1) as f64 / WARMUP as f64).min(1.0);
        let net = optim.step(lr, net, grads);
        self.state.step = step + 1;
        self.loss = lv;
        let line = self.checkpoint_due().then(|| {
            let judge = FrameJudge::new(self.judge.clone(), net.valid(), inner);
            let heldout = evaluate(&judge, data, held, self.judge.threshold);
            LogLine { heldout, loss: lv, out_of_time: false, step: self.state.step }
        });
        Ok(((net, optim), line))
    }

    fn checkpoint_due(&self) -> bool {
        self.state.step.is_multiple_of(self.cfg.eval_every.max(1)) && self.state.step < self.cfg.steps
    }

    fn save(&mut self, (net, optim): &Self::Net, elapsed_s: f64) -> Result<(), JudgeError> {
        // Its log lines carry no seconds: the state records them when it is saved.
        self.state.elapsed_s = elapsed_s;
        run::save(self.dir, net, optim, self.state)
    }

    fn progress(&mut self) {
        (self.on_step)(self.state.step, self.loss);
    }

    fn stopping(&mut self) {
        tracing::warn!(
            step = self.state.step,
            of = self.cfg.steps,
            "stopped: the session ends at this step (--resume continues)"
        );
    }
}

/// Trains, or goes on training, a judge of `data`'s label with the network and threshold
/// of `judge` (the folder's `judge.json` as it will be written), logging to `log`, until
/// `cfg.steps` or until the session stops ([`Driver::should_stop`]: out of time, or
/// Ctrl-C). The checkpoint is saved at every evaluation and when the session ends, so
/// `--resume` continues from where it stopped.
///
/// # Errors
/// [`JudgeError`] naming the log or checkpoint file that cannot be read or written, or the
/// dataset for a non-finite loss (naming the step) or too few episodes to hold any out.
#[allow(clippy::too_many_arguments)]
pub fn train_judge(
    data: &JudgeData,
    dataset: &Path,
    judge: &JudgeFile,
    cfg: &JudgeTrainConfig,
    log: &Path,
    session: JudgeSession,
    inner: &Device,
    on_step: &mut dyn FnMut(u64, f64),
) -> Result<JudgeOutcome, JudgeError> {
    let err = |what: String| JudgeError::Dataset { path: dataset.into(), what };
    let threshold = judge.threshold;
    let (train, held) = data.split();
    if train.is_empty() || held.is_empty() {
        return Err(err(format!(
            "{} episodes: need at least 10, every 10th is held out for evaluation",
            data.episodes.len()
        )));
    }
    let positives: Vec<usize> =
        train.iter().copied().filter(|&i| f64::from(data.labels[i]) > threshold).collect();
    if cfg.balance && positives.is_empty() {
        tracing::warn!("no training frame is above the threshold {threshold}; batches are not balanced");
    }
    let device = inner.clone().autodiff();
    device.seed(derive(cfg.seed, &[0x6a75_6467]));
    let mut net = JudgeNet::new(&judge.net, &device);
    let mut optim = AdamWConfig::new().with_weight_decay(1e-6).init();
    let mut state = State::default();
    if session.resume {
        (net, optim, state) = run::load(session.dir, net, optim)?;
    }
    let mut driver = Driver::start(log, "step", state.step, state.elapsed_s, session.clock)?;
    let held_episodes = data.held_out_episodes();
    // The last evaluation also reads the held-out episodes whole.
    let last_eval = |net: &JudgeNet| {
        let judge = FrameJudge::new(judge.clone(), net.valid(), inner);
        let mut m = evaluate(&judge, data, &held, threshold);
        let reading = Reading::rank(judge.file.persist_frames);
        let judged = judge_episodes(&judge, data, &held_episodes, &reading, threshold);
        m.episodes = Some(EpisodeReading {
            reading: Some(reading),
            ..read_judged(&judged, reading.persist, threshold)
        });
        m
    };
    let first = state.step;
    let mut steps = JudgeSteps {
        data,
        cfg,
        judge,
        sets: (&train, &positives, &held),
        devices: (&device, inner),
        dir: session.dir,
        state,
        loss: f64::NAN,
        on_step,
        dataset,
    };
    let (net, _) = driver.train(&mut steps, (net, optim))?.0;
    let (state, lv) = (steps.state, steps.loss);
    if state.step == 0 {
        return Ok(JudgeOutcome { judge: None, step: 0, elapsed_s: state.elapsed_s });
    }
    // The last evaluation, where the session ended (the run's last step, or where it stopped).
    let m = last_eval(&net);
    if state.step > first {
        let out_of_time = state.step < cfg.steps;
        driver.log(&LogLine { heldout: m, loss: lv, out_of_time, step: state.step })?;
    }
    Ok(JudgeOutcome { judge: Some((net.valid(), m)), step: state.step, elapsed_s: state.elapsed_s })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::folder::Label;
    use policies::net::NetConfig;

    #[test]
    fn metrics_count_each_side_of_the_threshold() {
        // Threshold 0.5. Labels 1, 1, 0, 0; estimates 0.9 (TP), 0.2 (FN), 0.7 (FP), 0.1 (TN).
        // |errors| 0.1 + 0.8 + 0.7 + 0.1 = 1.7, mean 0.425; accuracy 2/4; recall 1/2; precision 1/2.
        let m = metrics(&[0.9, 0.2, 0.7, 0.1], &[1.0, 1.0, 0.0, 0.0], 0.5);
        assert_eq!((m.frames, m.positives), (4, 2));
        assert!((m.mean_abs_error - 0.425).abs() < 1e-12);
        assert_eq!((m.accuracy, m.recall, m.precision), (0.5, Some(0.5), Some(0.5)));
        // Nothing above the threshold: no recall; nothing said above it: no precision.
        let m = metrics(&[0.1], &[0.2], 0.5);
        assert_eq!((m.accuracy, m.recall, m.precision), (1.0, None, None));
    }

    #[test]
    fn a_stopped_session_resumes_to_the_weights_of_an_uninterrupted_run() {
        // 10 episodes of 2 frames (16 x 16), labels alternating 0 / 1; episode 9 is
        // held out (2 frames).
        let size = 16;
        let n = 20;
        let data = JudgeData {
            frames: (0..n * size * size * 3).map(|i| (i % 251) as u8).collect(),
            labels: (0..n).map(|i| (i % 2) as f32).collect(),
            size,
            episodes: (0..10).map(|e| 2 * e..2 * e + 2).collect(),
        };
        let net = NetConfig::new().with_image_size(size).with_encoder_width(4).with_feature_dim(4);
        let judge = JudgeFile {
            pose_base: None,
            kind: "learned".into(),
            net,
            label: Label::Success,
            rule: None,
            threshold: 0.5,
            persist_frames: 1,
            steps: 5,
            heldout: JudgeMetrics::default(),
            provenance: crate::provenance::JudgeProvenance::default(),
        };
        let cfg = |steps| JudgeTrainConfig {
            steps,
            batch: 2,
            lr: 1e-3,
            seed: 0,
            balance: true,
            symmetries: false,
            eval_every: 2,
        };
        let root = tempfile::tempdir().unwrap();
        let device = Device::flex();
        let session = |name: &str, steps: u64, resume: bool, minutes: Option<f64>| {
            let (out, train) = (root.path().join(name), root.path().join(name).join(".train"));
            std::fs::create_dir_all(&out).unwrap();
            let s = JudgeSession { dir: &train, resume, clock: Clock::start(minutes) };
            let log = out.join("log.jsonl");
            train_judge(&data, root.path(), &judge, &cfg(steps), &log, s, &device, &mut |_, _| {}).unwrap()
        };
        let logged = |name: &str| -> Vec<u64> {
            let text = std::fs::read_to_string(root.path().join(name).join("log.jsonl")).unwrap();
            text.lines()
                .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["step"].as_u64().unwrap())
                .collect()
        };
        // Out of time before the first step: no judge yet, but a checkpoint to resume.
        let none = session("none", 5, false, Some(0.0));
        assert!(none.judge.is_none() && none.step == 0);
        assert!(root.path().join("none/.train/state.json").is_file());
        // Five steps in one session; three, then two more on --resume.
        let straight = session("straight", 5, false, None);
        assert_eq!(session("split", 3, false, None).step, 3);
        let split = session("split", 5, true, None);
        assert_eq!((straight.step, split.step), (5, 5));
        // The same weights: the same logits, bit for bit, on every frame (the files differ
        // in burn's parameter ids, which each process draws anew).
        let frames: Vec<&[u8]> = (0..n).map(|i| data.frame(i)).collect();
        let logits = |net: &JudgeNet| {
            net.forward(frames_to_tensor(&frames, size, &device)).into_data().try_to_vec::<f32>().unwrap()
        };
        let ((split_net, m), (straight_net, m_straight)) =
            (split.judge.expect("a judge"), straight.judge.expect("a judge"));
        assert_eq!(logits(&split_net), logits(&straight_net), "the resumed run's weights differ");
        assert_eq!(m, m_straight);
        assert_eq!(m.frames, 2);
        // The held-out episode (labels 0, 1) is read whole: it succeeds.
        let e = m.episodes.expect("the last evaluation reads whole episodes");
        assert_eq!((e.episodes, e.successes), (1, 1));
        // Evaluations every 2 steps and at each session's end, once per step.
        assert_eq!((logged("straight"), logged("split")), (vec![2, 4, 5], vec![2, 3, 4, 5]));
        // The run stopped at once resumes from its step-0 checkpoint to the same weights.
        let resumed = session("none", 5, true, None).judge.expect("a judge").0;
        assert_eq!(logits(&resumed), logits(&straight_net), "resumed from step 0");
    }

    #[test]
    fn episodes_succeed_when_any_frame_is_above_the_threshold() {
        // (judged, true) per episode: (T, T) agree, (T, F) false success, (F, T) missed,
        // (F, F) agree: 4 episodes, 2 successes, 2 agree, 1 false, 1 missed.
        let r = EpisodeReading::of([(true, true), (true, false), (false, true), (false, false)]);
        let want = EpisodeReading {
            reading: None,
            episodes: 4,
            successes: 2,
            agree: 2,
            false_successes: 1,
            missed_successes: 1,
        };
        assert_eq!(r, want);
    }

    #[test]
    fn bce_matches_its_definition() {
        let device = Device::flex();
        // z = 2, y = 1: max(2, 0) − 1·2 + log(1 + e^−2) = 0.126928;
        // z = −3, y = 0.25: max(−3, 0) − 0.25·(−3) + log(1 + e^−3) = 0.75 + 0.048587 = 0.798587.
        // Mean (0.126928 + 0.798587) / 2 = 0.462758.
        let z = Tensor::<2>::from_floats([[2.0], [-3.0]], &device);
        let y = Tensor::<2>::from_floats([[1.0], [0.25]], &device);
        let v: f32 = bce_with_logits(z, y).into_scalar();
        assert!((f64::from(v) - 0.462_758).abs() < 1e-5, "{v}");
    }
}
