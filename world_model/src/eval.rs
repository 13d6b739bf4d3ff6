//! Video-quality evaluation of a world model on held-out episodes (spec §9):
//! from 4 real context frames and the episode's recorded actions, roll out
//! autoregressively (chunks of F frames, the last one truncated) and compare
//! every generated frame with the real one — MSE on [-1, 1] pixels, and PSNR and
//! SSIM on uint8 as scikit-image computes them — per frame, averaged per video,
//! then over videos. Timing is generation wall time (U-Net + decoding) per frame.

use std::time::Instant;

use burn::tensor::{Tensor, TensorData};
use harness::image::{psnr, ssim};
use harness::rng::Rng;
use harness::seed::derive;
use serde::Serialize;

use crate::data::{EpisodeData, tensor_to_frames};
use crate::latents::normalise_action;
use crate::model::WorldModel;

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
}

/// One video's real and generated frames (HWC bytes), for filmstrips.
pub struct Video {
    /// Real frames after the context.
    pub real: Vec<Vec<u8>>,
    /// Generated frames.
    pub generated: Vec<Vec<u8>>,
}

/// Rolls out `len` frames after a 4-frame real context for each start step in
/// `starts` (batched); returns the generated frames per video and the seconds spent.
///
/// # Panics
/// Never for valid inputs; `starts` must leave `3 + len` frames in each episode.
pub fn rollout(
    wm: &WorldModel,
    data: &EpisodeData,
    starts: &[usize],
    len: usize,
    seed: u64,
) -> (Vec<Vec<Vec<u8>>>, f64) {
    let device = wm.device().clone();
    let (k, f_max) = (wm.cfg.unet.history, wm.cfg.future);
    let b = starts.len();
    let ctx: Vec<usize> = starts.iter().flat_map(|&t| t..t + k).collect();
    let t0 = Instant::now();
    let z = wm.encode(data.frames_tensor(&ctx, &device)); // [b k, C, s, s]
    let [_, c, s, _] = z.dims();
    let mut hist = z.reshape([b, k, c, s, s]);
    let mut rngs: Vec<Rng> = starts.iter().map(|&t| Rng::new(derive(seed, &[t as u64]))).collect();
    let mut out: Vec<Vec<Vec<u8>>> = vec![Vec::with_capacity(len); b];
    let mut done = 0;
    while done < len {
        let f = f_max.min(len - done);
        // a_{t+k-1+done+j} drives frame t+k+done+j.
        let acts: Vec<f32> = starts
            .iter()
            .flat_map(|&t| (0..f).flat_map(move |j| [0, 1].map(|d| (t + k - 1 + done + j, d))))
            .map(|(i, d)| normalise_action(data.actions[i * 2 + d]))
            .collect();
        let act = Tensor::<3>::from_data(TensorData::new(acts, [b, f, 2]), &device);
        let pred = wm.predict(hist.clone(), act, &mut rngs); // [b, f, C, s, s]
        let frames = tensor_to_frames(wm.decode(pred.clone().reshape([b * f, c, s, s])));
        for (i, fr) in frames.into_iter().enumerate() {
            out[i / f].push(fr);
        }
        hist = Tensor::cat(vec![hist, pred], 1).narrow(1, f, k);
        done += f;
    }
    (out, t0.elapsed().as_secs_f64())
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

/// Evaluates `wm` on videos starting at `starts`, each `len` generated frames long
/// (or to its episode's end when `len` is `None`), in batches of `batch`.
pub fn evaluate(
    wm: &WorldModel,
    name: &str,
    data: &EpisodeData,
    starts: &[(usize, usize)],
    horizon: &str,
    batch: usize,
    seed: u64,
) -> (EvalRow, Vec<Video>) {
    let k = wm.cfg.unet.history;
    let (mut sums, mut frames, mut secs) = ([0.0f64; 3], 0usize, 0.0);
    let mut videos = Vec::new();
    // Group videos of equal length so that each batch rolls out the same number of frames.
    let mut order: Vec<(usize, usize)> = starts.to_vec();
    order.sort_by_key(|&(t, len)| (len, t));
    for group in order.chunk_by(|a, b| a.1 == b.1) {
        for chunk in group.chunks(batch.max(1)) {
            let len = chunk[0].1;
            let st: Vec<usize> = chunk.iter().map(|&(t, _)| t).collect();
            let (videos_gen, s) = rollout(wm, data, &st, len, seed);
            secs += s;
            for (&t, g) in st.iter().zip(videos_gen) {
                let real: Vec<Vec<u8>> = (0..len).map(|j| data.frame(t + k + j).to_vec()).collect();
                let mut v = [0.0f64; 3];
                for (r, x) in real.iter().zip(&g) {
                    let (m, p, q) = frame_metrics(r, x, data.size);
                    v[0] += m;
                    v[1] += p;
                    v[2] += q;
                }
                for (acc, x) in sums.iter_mut().zip(v) {
                    *acc += x / len as f64;
                }
                frames += len;
                videos.push(Video { real, generated: g });
            }
        }
    }
    let n = videos.len().max(1) as f64;
    let row = EvalRow {
        name: name.to_string(),
        objective: wm.cfg.objective.name().to_string(),
        horizon: horizon.to_string(),
        mse: sums[0] / n,
        psnr: sums[1] / n,
        ssim: sums[2] / n,
        ms_per_frame: 1e3 * secs / frames.max(1) as f64,
        frames,
        videos: videos.len(),
    };
    (row, videos)
}
