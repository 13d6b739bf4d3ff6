//! Video-quality evaluation of a world model on held-out episodes (spec §9):
//! from 4 real context frames and the episode's recorded actions, roll out
//! autoregressively (chunks of F frames, the last one truncated) and compare
//! every generated frame with the real one — MSE on [-1, 1] pixels, and PSNR and
//! SSIM on uint8 as scikit-image computes them — per frame, averaged per video,
//! then over videos. Timing is generation wall time (U-Net + decoding) per frame.
//! An anchored model also sees its episode's first frame, as in `rank`.

use std::time::Instant;

use harness::image::{psnr, ssim};
use harness::rng::Rng;
use harness::seed::derive;
use serde::Serialize;

use crate::data::EpisodeData;
use crate::model::WorldModel;
use crate::rollout::{Rollout, RolloutError};
use nn::frames::tensor_to_frames;

/// The metrics of one model at one horizon.
#[derive(Clone, Debug, Serialize)]
pub struct EvalRow {
    /// Model name (its folder name).
    pub name: String,
    /// Objective.
    pub objective: String,
    /// "64" (4 real + 60 generated) or "episode" (whole episodes).
    pub horizon: String,
    /// Mean per-frame MSE on [-1, 1] pixels.
    pub mse: f64,
    /// Mean per-frame PSNR (dB, uint8).
    pub psnr: f64,
    /// Mean per-frame SSIM (uint8, data range 255).
    pub ssim: f64,
    /// Generation time per frame (ms) at the evaluation's batch size.
    pub ms_per_frame: f64,
    /// Generated frames evaluated.
    pub frames: usize,
    /// Videos evaluated.
    pub videos: usize,
    /// Mean SSIM at given generated frames (where along a rollout quality is lost).
    pub ssim_curve: Vec<SsimPoint>,
    /// Each video's own means, by its first context step (which videos lose the quality).
    pub per_video: Vec<VideoMetrics>,
    /// 95% interval of `ssim`, when the caller knows which episode each video is from
    /// (a bootstrap over episodes: windows of one episode overlap).
    pub ssim_ci: Option<[f64; 2]>,
}

/// One video's per-frame metrics averaged over its generated frames.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct VideoMetrics {
    /// Step index (in the dataset) of its first context frame.
    pub start: usize,
    /// Mean MSE on [-1, 1] pixels.
    pub mse: f64,
    /// Mean PSNR (dB).
    pub psnr: f64,
    /// Mean SSIM.
    pub ssim: f64,
}

/// Generated frames (0 = the first after the context) at which [`EvalRow::ssim_curve`]
/// reports SSIM; those beyond a video's length are skipped for it.
pub const SSIM_CURVE_AT: [usize; 8] = [0, 4, 8, 16, 32, 59, 128, 256];

/// Mean SSIM of one generated frame index over the videos that reach it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SsimPoint {
    /// Generated frame index (0 = the first after the context).
    pub frame: usize,
    /// Mean SSIM there.
    pub ssim: f64,
    /// Videos that reach it.
    pub videos: usize,
}

/// One video's real and generated frames (HWC bytes), for filmstrips and scoring.
pub struct Video {
    /// Step index (in the dataset) of its first context frame.
    pub start: usize,
    /// Real frames after the context.
    pub real: Vec<Vec<u8>>,
    /// Generated frames.
    pub generated: Vec<Vec<u8>>,
}

/// One video's frames, HWC bytes each.
pub type Frames = Vec<Vec<u8>>;

/// A batch of evaluation videos whose rollout failed (non-finite latents, or actions the
/// model does not read), naming the model and the videos.
#[derive(Debug, thiserror::Error)]
#[error(
    "world model {model}, a batch of videos whose context starts at steps {}: {source}",
    starts.iter().map(usize::to_string).collect::<Vec<_>>().join(", ")
)]
pub struct EvalError {
    /// The model's name (empty from [`rollout`], which does not know it).
    pub model: String,
    /// Each video's first context step.
    pub starts: Vec<usize>,
    /// Why the rollout stopped.
    #[source]
    pub source: RolloutError,
}

/// Rolls out `len` frames after a 4-frame real context for each start step in
/// `starts` (batched); returns the generated frames per video and the seconds spent.
///
/// # Errors
/// [`EvalError`] for non-finite latents, naming the videos (their first context steps).
///
/// # Panics
/// Never for valid inputs; `starts` must leave `3 + len` frames in each episode.
pub fn rollout(
    wm: &WorldModel,
    data: &EpisodeData,
    starts: &[usize],
    len: usize,
    seed: u64,
) -> Result<(Vec<Frames>, f64), EvalError> {
    let device = wm.device().clone();
    let (k, f_max) = (wm.cfg.unet.history, wm.cfg.future);
    let b = starts.len();
    let ctx: Vec<usize> = starts.iter().flat_map(|&t| t..t + k).collect();
    let firsts: Vec<usize> = starts
        .iter()
        .map(|&t| data.episodes.iter().find(|r| r.contains(&t)).map_or(t, |r| r.start))
        .collect();
    let t0 = Instant::now();
    let z = wm.encode(data.frames_tensor(&ctx, &device)); // [b k, C, s, s]
    let [_, c, s, _] = z.dims();
    let hist = z.reshape([b, k, c, s, s]); // [b, K, C, s, s]
    // Each video's episode's first frame; a model without an anchor ignores it.
    let anchor = if wm.uses_anchor() {
        wm.encode(data.frames_tensor(&firsts, &device)) // [b, C, s, s]
    } else {
        hist.clone().narrow(1, 0, 1).reshape([b, c, s, s])
    };
    let mut roll = Rollout::new(hist, anchor);
    let mut rngs: Vec<Rng> = starts.iter().map(|&t| Rng::new(derive(seed, &[t as u64]))).collect();
    let mut out: Vec<Frames> = vec![Vec::with_capacity(len); b];
    while roll.generated() < len {
        let (done, f) = (roll.generated(), f_max.min(len - roll.generated()));
        // a_{t+k-1+done+j} drives frame t+k+done+j.
        let d = data.action_dim;
        let action = |r: usize, j: usize| {
            let t = starts[r] + k - 1 + done + j;
            &data.actions[t * d..(t + 1) * d]
        };
        let pred = roll.step(wm, f, action, &mut rngs).map_err(|source| EvalError {
            model: String::new(),
            starts: starts.to_vec(),
            source,
        })?; // [b, f, C, s, s]
        let frames = tensor_to_frames(wm.decode(pred.reshape([b * f, c, s, s])));
        for (i, fr) in frames.into_iter().enumerate() {
            out[i / f].push(fr);
        }
    }
    Ok((out, t0.elapsed().as_secs_f64()))
}

/// Per-frame metrics of generated vs real frames: (mse on [-1, 1], psnr, ssim).
fn frame_metrics(real: &[u8], generated: &[u8], size: usize) -> (f64, f64, f64) {
    let mse = real
        .iter()
        .zip(generated)
        .map(|(a, b)| ((f64::from(*a) - f64::from(*b)) / 127.5).powi(2))
        .sum::<f64>()
        / real.len().max(1) as f64;
    (mse, psnr(real, generated).min(100.0), ssim(real, generated, size, size, 3).unwrap_or(0.0))
}

/// Per-video metrics (in the order added), averaged into an [`EvalRow`].
#[derive(Default)]
struct Tally {
    per_video: Vec<VideoMetrics>,
    frames: usize,
    /// SSIM sum and video count at each of [`SSIM_CURVE_AT`].
    curve: [(f64, usize); SSIM_CURVE_AT.len()],
}

impl Tally {
    /// Adds the video whose context starts at step `start`: per-frame metrics
    /// averaged over its frames.
    fn add(&mut self, start: usize, real: &[Vec<u8>], generated: &[Vec<u8>], size: usize) {
        let mut v = [0.0f64; 3];
        for (j, (r, x)) in real.iter().zip(generated).enumerate() {
            let (m, p, q) = frame_metrics(r, x, size);
            v[0] += m;
            v[1] += p;
            v[2] += q;
            if let Some(i) = SSIM_CURVE_AT.iter().position(|&f| f == j) {
                self.curve[i].0 += q;
                self.curve[i].1 += 1;
            }
        }
        let v = v.map(|x| x / real.len().max(1) as f64);
        self.per_video.push(VideoMetrics { start, mse: v[0], psnr: v[1], ssim: v[2] });
        self.frames += real.len();
    }

    fn row(mut self, name: &str, objective: &str, horizon: &str, secs: f64) -> EvalRow {
        // Means over videos, summed in the order the videos were added.
        let n = self.per_video.len().max(1) as f64;
        let mean = |f: fn(&VideoMetrics) -> f64| self.per_video.iter().map(f).sum::<f64>() / n;
        let (mse, psnr, ssim) = (mean(|v| v.mse), mean(|v| v.psnr), mean(|v| v.ssim));
        let videos = self.per_video.len();
        self.per_video.sort_by_key(|m| m.start);
        EvalRow {
            name: name.to_string(),
            objective: objective.to_string(),
            horizon: horizon.to_string(),
            mse,
            psnr,
            ssim,
            ms_per_frame: 1e3 * secs / self.frames.max(1) as f64,
            frames: self.frames,
            videos,
            ssim_curve: SSIM_CURVE_AT
                .iter()
                .zip(self.curve)
                .filter(|(_, (_, n))| *n > 0)
                .map(|(&frame, (sum, n))| SsimPoint { frame, ssim: sum / n as f64, videos: n })
                .collect(),
            per_video: self.per_video,
            ssim_ci: None,
        }
    }
}

/// Real frames `t + k .. t + k + len` of a video whose context starts at `t`.
fn real_frames(data: &EpisodeData, t: usize, k: usize, len: usize) -> Vec<Vec<u8>> {
    (0..len).map(|j| data.frame(t + k + j).to_vec()).collect()
}

/// The reference every world model must beat: "nothing moves", the last context
/// frame repeated for the whole video (no model, no cost). A model scoring below it
/// predicts motion worse than not predicting any.
pub fn persistence(data: &EpisodeData, starts: &[(usize, usize)], k: usize, horizon: &str) -> EvalRow {
    let mut tally = Tally::default();
    for &(t, len) in starts {
        let last = data.frame(t + k - 1).to_vec();
        tally.add(t, &real_frames(data, t, k, len), &vec![last; len], data.size);
    }
    tally.row("persistence", "none", horizon, 0.0)
}

/// Frames encoded and decoded per batch by [`round_trip`].
const ROUND_TRIP_BATCH: usize = 32;

/// The latent family's ceiling: the real future frames of the same videos encoded and
/// decoded by `wm`'s own autoencoder, with no dynamics. A rollout cannot be better than
/// its decoder's rendering of the true future, so the row's distance from a perfect
/// score is the autoencoder's share of the error and the model's distance from this
/// row is the dynamics' share. Named `"<name>:autoencoder"`, objective `"round-trip"`;
/// `None` for a pixel-space model (no codec, nothing lost). With a `view`, the model's
/// input frames are round-tripped and completed, as its rollouts are.
pub fn round_trip(
    wm: &WorldModel,
    (name, view): (&str, Option<&View>),
    data: &EpisodeData,
    starts: &[(usize, usize)],
    horizon: &str,
) -> Option<EvalRow> {
    wm.cfg.autoencoder.as_ref()?;
    let k = wm.cfg.unet.history;
    let inputs = view.map_or(data, |v| v.inputs);
    let device = wm.device().clone();
    let (mut tally, t0) = (Tally::default(), Instant::now());
    for &(t, len) in starts {
        let steps: Vec<usize> = (t + k..t + k + len).collect();
        let mut decoded = Vec::with_capacity(len);
        for chunk in steps.chunks(ROUND_TRIP_BATCH) {
            let z = wm.encode(inputs.frames_tensor(chunk, &device)); // [n, C, s, s]
            decoded.extend(tensor_to_frames(wm.decode(z))); // n × [H, W, 3] bytes
        }
        if let Some(v) = view {
            (v.complete)(t, &mut decoded);
        }
        tally.add(t, &real_frames(data, t, k, len), &decoded, data.size);
    }
    Some(tally.row(&format!("{name}:autoencoder"), "round-trip", horizon, t0.elapsed().as_secs_f64()))
}

/// What a model reads and how its frames are completed, when its inputs are not the
/// dataset's frames: a goal-free model reads the scenes re-rendered without the
/// static goal, and each generated frame gets the goal back before it is compared
/// with the real one.
pub struct View<'a> {
    /// The frames the model reads (same steps as the dataset).
    pub inputs: &'a EpisodeData,
    /// Completes the generated frames of the video whose context starts at a step.
    pub complete: &'a (dyn Fn(usize, &mut [Vec<u8>]) + Sync),
}

/// Evaluates `wm` on videos starting at `starts`, each `len` generated frames long
/// (or to its episode's end when `len` is `None`), in batches of `batch`; with a
/// `view`, the model reads `view.inputs` and its frames are completed before the
/// comparison with `data`'s.
///
/// # Errors
/// [`EvalError`]: a rollout with non-finite latents, naming the model and the videos.
pub fn evaluate(
    wm: &WorldModel,
    (name, view): (&str, Option<&View>),
    data: &EpisodeData,
    starts: &[(usize, usize)],
    horizon: &str,
    batch: usize,
    seed: u64,
) -> Result<(EvalRow, Vec<Video>), EvalError> {
    let k = wm.cfg.unet.history;
    let (mut tally, mut secs) = (Tally::default(), 0.0);
    let mut videos = Vec::new();
    // Group videos of equal length so that each batch rolls out the same number of frames.
    let mut order: Vec<(usize, usize)> = starts.to_vec();
    order.sort_by_key(|&(t, len)| (len, t));
    for group in order.chunk_by(|a, b| a.1 == b.1) {
        for chunk in group.chunks(batch.max(1)) {
            let len = chunk[0].1;
            let st: Vec<usize> = chunk.iter().map(|&(t, _)| t).collect();
            let (videos_gen, s) = rollout(wm, view.map_or(data, |v| v.inputs), &st, len, seed)
                .map_err(|e| EvalError { model: name.to_string(), ..e })?;
            secs += s;
            for (&t, mut g) in st.iter().zip(videos_gen) {
                if let Some(v) = view {
                    (v.complete)(t, &mut g);
                }
                let real = real_frames(data, t, k, len);
                tally.add(t, &real, &g, data.size);
                videos.push(Video { start: t, real, generated: g });
            }
        }
    }
    Ok((tally.row(name, wm.cfg.objective.name(), horizon, secs), videos))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn persistence_compares_the_last_context_frame_with_the_future() {
        // One episode of 6 frames of 8x8: frames 0–4 all 100, frame 5 all 110.
        let px = 8 * 8 * 3;
        let mut frames = vec![100u8; 6 * px];
        frames[5 * px..].fill(110);
        let data = EpisodeData {
            frames,
            actions: vec![0.0; 12],
            action_dim: 2,
            size: 8,
            episodes: std::iter::once(0..6).collect(),
            source: std::path::PathBuf::new(),
        };
        // Context 0..4, last context frame 3; video = frames 4 and 5.
        let row = persistence(&data, &[(0, 2)], 4, "64");
        // MSE: frame 4: 0; frame 5: (10 / 127.5)² = 0.0061515; mean 0.0030757.
        assert!((row.mse - 0.5 * (10.0f64 / 127.5).powi(2)).abs() < 1e-9, "{}", row.mse);
        // PSNR: frame 4: capped at 100; frame 5: 10·log10(255² / 10²) = 28.1308; mean 64.0654.
        assert!((row.psnr - 0.5 * (100.0 + 20.0 * (25.5f64).log10())).abs() < 1e-6, "{}", row.psnr);
        assert_eq!((row.frames, row.videos), (2, 1));
        // SSIM by frame: frame 0 equals its real frame (SSIM 1); frame 1 is not a curve
        // point, and frames 4, 8, … lie beyond this 2-frame video.
        assert_eq!(row.ssim_curve, vec![SsimPoint { frame: 0, ssim: 1.0, videos: 1 }]);
        // One video, so its own means are the row's.
        assert_eq!(
            row.per_video,
            vec![VideoMetrics { start: 0, mse: row.mse, psnr: row.psnr, ssim: row.ssim }]
        );
        // Two videos, given out of order: the one from step 1 (context 1..5, last context
        // frame 4, video = frame 5) has MSE (10 / 127.5)² = 0.0061515; rows come sorted
        // by start, and the row's MSE is the mean of the two videos' means.
        let row = persistence(&data, &[(1, 1), (0, 2)], 4, "64");
        let mse: Vec<(usize, f64)> = row.per_video.iter().map(|v| (v.start, v.mse)).collect();
        let one = (10.0f64 / 127.5).powi(2);
        assert_eq!(mse.iter().map(|m| m.0).collect::<Vec<_>>(), vec![0, 1]);
        assert!((mse[0].1 - 0.5 * one).abs() < 1e-12 && (mse[1].1 - one).abs() < 1e-12, "{mse:?}");
        assert!((row.mse - 0.75 * one).abs() < 1e-12, "{}", row.mse);
    }

    #[test]
    fn a_pixel_space_model_has_no_round_trip_reference() {
        use crate::codec::FrameCodec;
        use crate::model::WorldModelConfig;
        use crate::unet::UNetConfig;
        let device = burn::tensor::Device::flex();
        let unet = UNetConfig { model_channels: 16, ..UNetConfig::pusht_latent(3) };
        let cfg = WorldModelConfig::pixels(unet.clone(), 8);
        let wm = WorldModel::from_parts(cfg, FrameCodec::pixels(8), unet.init(&device), &device);
        let data = EpisodeData {
            frames: vec![0; 6 * 192],
            actions: vec![0.0; 12],
            action_dim: 2,
            size: 8,
            episodes: std::iter::once(0..6).collect(),
            source: std::path::PathBuf::new(),
        };
        assert!(round_trip(&wm, ("wm", None), &data, &[(0, 2)], "64").is_none());
    }
}
