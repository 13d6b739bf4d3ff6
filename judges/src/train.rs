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
//! Training takes minutes to an hour, so a run does not resume. A run that reaches
//! its time limit (`--max-minutes`) ends there: the judge trained so far is
//! evaluated and written, with the steps it took. Ctrl-C abandons the run, and
//! the folder is written, atomically, only when the run ends.

use std::path::Path;

use burn::module::Module;
use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};
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

/// Trains a judge of `data`'s label with the network and threshold of `judge`
/// (the folder's `judge.json` as it will be written). `out_of_time` is asked
/// before each step: once it says yes, training ends there. Returns the judge
/// (inference device), its held-out metrics and the steps it took; `None` when
/// stopped (Ctrl-C) or out of time before the first step.
///
/// # Errors
/// [`JudgeError`] naming `log` for an unwritable log, or the dataset for a
/// non-finite loss (naming the step) or too few episodes to hold any out.
#[allow(clippy::too_many_arguments)]
pub fn train_judge(
    data: &JudgeData,
    dataset: &Path,
    judge: &JudgeFile,
    cfg: &JudgeTrainConfig,
    log: &Path,
    out_of_time: &mut dyn FnMut() -> bool,
    inner: &Device,
    on_step: &mut dyn FnMut(u64, f64),
) -> Result<Option<(JudgeNet, JudgeMetrics, u64)>, JudgeError> {
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
    let mut logf =
        std::fs::File::create(log).map_err(|source| JudgeError::Io { path: log.into(), source })?;
    let s = data.size;
    let eval = |net: &JudgeNet| {
        evaluate(&FrameJudge::new(judge.clone(), net.valid(), inner), data, &held, threshold)
    };
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
    let mut log_line = |line: &LogLine| {
        harness::runfile::append_line(&mut logf, line)
            .map_err(|source| JudgeError::Io { path: log.into(), source })
    };
    let (mut lv, mut done) = (f64::NAN, 0);
    for step in 0..cfg.steps {
        if harness::stop::requested() {
            return Ok(None);
        }
        if out_of_time() {
            tracing::warn!(step, of = cfg.steps, "out of time: the judge ends at this step");
            break;
        }
        let mut rng = Rng::new(derive(cfg.seed, &[step]));
        let idx: Vec<(usize, u8)> = (0..cfg.batch)
            .map(|j| {
                let pool =
                    if cfg.balance && !positives.is_empty() && j % 2 == 1 { &positives } else { &train };
                let k = if cfg.symmetries { rng.below(8) as u8 } else { 0 };
                (pool[rng.below(pool.len() as u64) as usize], k)
            })
            .collect();
        let owned: Vec<Vec<u8>> = idx.iter().map(|&(i, k)| augment_frame(data.frame(i), s, k)).collect();
        let frames: Vec<&[u8]> = owned.iter().map(Vec::as_slice).collect();
        let y: Vec<f32> = idx.iter().map(|&(i, _)| data.labels[i].clamp(0.0, 1.0)).collect();
        let y = Tensor::from_data(TensorData::new(y, [cfg.batch, 1]), &device);
        let loss = bce_with_logits(net.forward(frames_to_tensor(&frames, s, &device)), y);
        lv = loss.clone().into_scalar::<f32>().into();
        if !lv.is_finite() {
            return Err(err(format!("non-finite judge loss at step {step}")));
        }
        let grads = GradientsParams::from_grads(loss.backward(), &net);
        let lr = cfg.lr * ((step + 1) as f64 / WARMUP as f64).min(1.0);
        net = optim.step(lr, net, grads);
        done = step + 1;
        on_step(done, lv);
        if done.is_multiple_of(cfg.eval_every.max(1)) && done < cfg.steps {
            log_line(&LogLine { heldout: eval(&net), loss: lv, out_of_time: false, step: done })?;
        }
    }
    if done == 0 {
        return Ok(None);
    }
    // The last evaluation, where training ended (its last step, or out of time).
    let m = last_eval(&net);
    log_line(&LogLine { heldout: m, loss: lv, out_of_time: done < cfg.steps, step: done })?;
    Ok(Some((net.valid(), m, done)))
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
    fn out_of_time_ends_training_with_the_judge_so_far() {
        // 10 episodes of 2 frames (16 x 16), labels alternating 0 / 1; episode 9 is
        // held out (2 frames). The clock runs out before the 4th of 10 steps.
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
            steps: 10,
            heldout: JudgeMetrics::default(),
            provenance: crate::provenance::JudgeProvenance::default(),
        };
        let cfg = JudgeTrainConfig {
            steps: 10,
            batch: 2,
            lr: 1e-3,
            seed: 0,
            balance: true,
            symmetries: false,
            eval_every: 100,
        };
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("log.jsonl");
        let device = Device::flex();
        let mut asked = 0;
        let mut clock = || {
            asked += 1;
            asked > 3
        };
        let out = train_judge(&data, dir.path(), &judge, &cfg, &log, &mut clock, &device, &mut |_, _| {});
        let (_, m, steps) = out.unwrap().expect("the judge trained so far");
        assert_eq!((steps, m.frames), (3, 2));
        // The held-out episode (labels 0, 1) is read whole: it succeeds.
        let e = m.episodes.expect("the last evaluation reads whole episodes");
        assert_eq!((e.episodes, e.successes), (1, 1));
        assert_eq!(e.agree + e.missed_successes, 1);
        // One log line, the evaluation where training ended (step 3).
        let text = std::fs::read_to_string(&log).unwrap();
        let line: serde_json::Value = serde_json::from_str(text.trim()).unwrap();
        assert_eq!((line["step"].as_u64(), line["out_of_time"].as_bool()), (Some(3), Some(true)));
        // Out of time before the first step: nothing trained, nothing returned.
        let out = train_judge(&data, dir.path(), &judge, &cfg, &log, &mut || true, &device, &mut |_, _| {});
        assert!(out.unwrap().is_none());
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
