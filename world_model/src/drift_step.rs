//! The drifting objective's loss for one training batch (spec §2, §4, §7).
//!
//! Phase 1 (`chunks = 1`) predicts one chunk of F frames from true history.
//! With self-forcing (phase 2, spec §7, `chunks = L > 1`) each of the N samples of
//! a context keeps its own rollout: chunk i's history is the last K frames of that
//! sample's own detached predictions (true frames at first), and its positive is
//! the true chunk i — so the model learns from the drifted histories it will meet
//! in a closed-loop rollout. The chunks' losses are averaged; no gradient flows
//! through the history, which makes this equal to accumulating per-chunk gradients.
//!
//! How a chunk's latents are cut into drift problems is a [`FieldKind`]; motion
//! weighting ([`crate::motion`]) weighs per-token problems by how much the true
//! frame moved since the true frame before the chunk.

use burn::tensor::{Distribution, Tensor};
use serde::{Deserialize, Serialize};

use crate::drift::{Negatives, drift_loss_weighted};
use crate::latents::{Latents, Window};
use crate::motion::{MotionWeighting, token_distances};
use crate::unet::UNet;
use crate::unet::accent::training_alpha;

/// The unit of the drifting loss (spec §2): one drift problem per frame, or one per
/// latent cell ("token").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FieldKind {
    /// Each future frame is one flat vector (C·s·s dims), as the pixel-space Push-T
    /// model matches whole frames.
    #[default]
    Frame,
    /// Each latent cell of each future frame is its own problem (C dims, own scale
    /// and normalisation), as DriftWorld's latent family matches `latent_spatial`
    /// tokens: many low-dimensional problems instead of one 1152-dimensional one.
    Token,
}

impl FieldKind {
    /// Cuts generated latents `[b n, C, F, s, s]` (n samples per context) and the
    /// positives `[b, F, C, s, s]` into drift problems: `([p, n, d], [p, 1, d])`.
    pub fn problems(self, generated: Tensor<5>, pos: Tensor<5>, b: usize) -> (Tensor<3>, Tensor<3>) {
        let [bn, c, f, s, _] = generated.dims();
        let n = bn / b;
        let generated = generated.reshape([b, n, c, f, s * s]);
        let pos = pos.reshape([b, f, c, s * s]);
        match self {
            // [b, n, C, F, ss] -> [b, F, n, C, ss] -> [b F, n, C ss]
            Self::Frame => (
                generated.permute([0, 3, 1, 2, 4]).reshape([b * f, n, c * s * s]),
                pos.reshape([b * f, 1, c * s * s]),
            ),
            // [b, n, C, F, ss] -> [b, F, ss, n, C] -> [b F ss, n, C]
            Self::Token => (
                generated.permute([0, 3, 4, 1, 2]).reshape([b * f * s * s, n, c]),
                pos.permute([0, 1, 3, 2]).reshape([b * f * s * s, 1, c]),
            ),
        }
    }
}

/// What [`drifting_loss`] needs besides the batch.
pub struct DriftSetup<'a> {
    /// How chunks are cut into drift problems.
    pub field: FieldKind,
    /// Drift temperatures.
    pub temperatures: &'a [f32],
    /// Per-token motion weighting (token fields only).
    pub motion: Option<&'a MotionWeighting>,
    /// Chunks per rollout: 1 = phase 1, L > 1 = self-forcing.
    pub chunks: usize,
    /// Action accentuation (spec §3): a per-context α, fed to the U-Net, and the true
    /// current frame as an extra negative of weight (α − 1)(N − 1).
    pub accentuation: bool,
}

fn host<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default()
}

/// The batch's drifting loss (mean over chunks) and its per-temperature `loss_R`
/// (mean over chunks). `windows` hold `chunks · F` targets and actions, and every
/// frame they name is already in `latents`.
///
/// # Shapes
/// - `hist`: `[b n, C, K, s, s]`, each context's true history repeated n times
/// - `anchor`: `[b n, C, s, s]`, each context's episode's first frame (anchored U-Nets)
/// - `act`: `[b n, chunks·F, 2]` normalised actions
pub fn drifting_loss(
    unet: &UNet,
    latents: &Latents,
    windows: &[Window],
    mut hist: Tensor<5>,
    anchor: Option<Tensor<4>>,
    act: Tensor<3>,
    setup: &DriftSetup,
) -> (Tensor<1>, Vec<f32>) {
    let device = hist.device();
    let [bn, c, k, s, _] = hist.dims();
    let b = windows.len();
    let f = windows[0].targets.len() / setup.chunks.max(1);
    let n = bn / b.max(1);
    let mut total: Option<Tensor<1>> = None;
    let mut loss_r = vec![0.0f32; setup.temperatures.len()];
    // One α per context (shared by its n samples and its chunks), from two uniform draws.
    let alphas: Option<Vec<f32>> = setup.accentuation.then(|| {
        let u = Tensor::<2>::random([b, 2], Distribution::Uniform(0.0, 1.0), &device);
        host(u).chunks(2).map(|p| training_alpha(p[0], p[1])).collect()
    });
    let alpha = alphas.as_ref().map(|al| {
        let per_clip: Vec<f32> = al.iter().flat_map(|&a| std::iter::repeat_n(a, n)).collect();
        Tensor::<1>::from_floats(per_clip.as_slice(), &device) // [b n]
    });
    for i in 0..setup.chunks.max(1) {
        let noise = Tensor::<5>::random([bn, c, f, s, s], Distribution::Normal(0.0, 1.0), &device);
        let a = act.clone().narrow(1, i * f, f); // [b n, F, 2]
        let out = unet.forward_accentuated(noise, hist.clone(), a, anchor.clone(), None, alpha.clone()); // [b n, C, F, s, s]
        let pos_idx: Vec<usize> =
            windows.iter().flat_map(|w| w.targets[i * f..(i + 1) * f].iter().copied()).collect();
        let pos = latents.tensor(&pos_idx, f, &device); // [b, F, C, s, s]
        let weights = setup.motion.map(|m| {
            // δ of each (context, frame, cell) against the true frame before the chunk.
            let before = |w: &Window| if i == 0 { w.history[k - 1] } else { w.targets[i * f - 1] };
            let last_idx: Vec<usize> =
                windows.iter().flat_map(|w| std::iter::repeat_n(before(w), f)).collect();
            let last = latents.tensor(&last_idx, f, &device); // [b, F, C, s, s]
            let delta = token_distances(&host(pos.clone()), &host(last), c, s * s); // [b F, ss]
            Tensor::<1>::from_floats(m.weights(&delta, s * s).as_slice(), &device) // [b F ss]
        });
        let negatives = alphas.as_ref().map(|al| {
            // Each frame's true predecessor o_t (the last history frame, then the true
            // frames before it), cut into the same problems as the positives.
            let prev = |w: &Window, j: usize| {
                if i * f + j == 0 { w.history[k - 1] } else { w.targets[i * f + j - 1] }
            };
            let prev_idx: Vec<usize> = windows.iter().flat_map(|w| (0..f).map(move |j| prev(w, j))).collect();
            let prev = latents.tensor(&prev_idx, f, &device); // [b, F, C, s, s]
            let (_, y) = setup.field.problems(out.clone(), prev, b); // [p, 1, d]
            let per = y.dims()[0] / b; // problems per context
            let w: Vec<f32> =
                al.iter().flat_map(|&a| std::iter::repeat_n((a - 1.0) * (n as f32 - 1.0), per)).collect();
            let p = w.len();
            Negatives { y, w: Tensor::<1>::from_floats(w.as_slice(), &device).reshape([p, 1]) }
        });
        let (generated, positives) = setup.field.problems(out.clone(), pos, b);
        let (loss, field) =
            drift_loss_weighted(generated, negatives.as_ref(), &positives, setup.temperatures, weights);
        for (acc, v) in loss_r.iter_mut().zip(&field.loss_r) {
            *acc += v / setup.chunks.max(1) as f32;
        }
        total = Some(match total {
            Some(t) => t + loss,
            None => loss,
        });
        // Each sample's next history: its own last K frames, without gradient.
        hist = Tensor::cat(vec![hist, out.detach()], 2).narrow(2, f, k); // [b n, C, K, s, s]
    }
    let loss = total.map_or_else(|| Tensor::zeros([1], &device), |t| t / setup.chunks.max(1) as f64);
    (loss, loss_r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::{Device, TensorData};

    /// Generated `[b n, C, F, s, s]` with value 1000·ctx + 100·sample + 10·c + f + cell/100.
    fn tagged(b: usize, n: usize, c: usize, f: usize, s: usize) -> Tensor<5> {
        let mut v = Vec::new();
        for (bi, ni, ci, fi, cell) in all_indices(b, n, c, f, s * s) {
            v.push((1000 * bi + 100 * ni + 10 * ci + fi) as f32 + cell as f32 / 100.0);
        }
        Tensor::from_data(TensorData::new(v, [b * n, c, f, s, s]), &Device::flex())
    }

    fn all_indices(
        b: usize,
        n: usize,
        c: usize,
        f: usize,
        cells: usize,
    ) -> impl Iterator<Item = (usize, usize, usize, usize, usize)> {
        (0..b).flat_map(move |bi| {
            (0..n).flat_map(move |ni| {
                (0..c).flat_map(move |ci| {
                    (0..f).flat_map(move |fi| (0..cells).map(move |x| (bi, ni, ci, fi, x)))
                })
            })
        })
    }

    #[test]
    fn token_problems_hold_one_cell_of_one_frame_of_one_context() {
        let (b, n, c, f, s) = (2, 3, 2, 4, 2);
        let generated = tagged(b, n, c, f, s);
        // Positives [b, F, C, s, s] tagged 1000·ctx + 10·c + f + cell/100.
        let pos: Vec<f32> = (0..b)
            .flat_map(|bi| {
                (0..f).flat_map(move |fi| {
                    (0..c).flat_map(move |ci| {
                        (0..s * s).map(move |x| (1000 * bi + 10 * ci + fi) as f32 + x as f32 / 100.0)
                    })
                })
            })
            .collect();
        let pos = Tensor::<5>::from_data(TensorData::new(pos, [b, f, c, s, s]), &Device::flex());
        let (g, p) = FieldKind::Token.problems(generated, pos, b);
        assert_eq!(g.dims(), [b * f * s * s, n, c]);
        assert_eq!(p.dims(), [b * f * s * s, 1, c]);
        let g: Vec<f32> = g.into_data().try_into_vec::<f32>().unwrap();
        let p: Vec<f32> = p.into_data().try_into_vec::<f32>().unwrap();
        // Problem index ((ctx·F + f)·cells + cell); take ctx 1, frame 2, cell 3: index (1·4 + 2)·4 + 3 = 27.
        // Its sample 2, channel 1 is 1000 + 200 + 10 + 2 + 0.03 = 1212.03.
        let at = |prob: usize, sample: usize, ch: usize| g[(prob * n + sample) * c + ch];
        assert!((at(27, 2, 1) - 1212.03).abs() < 1e-3, "{}", at(27, 2, 1));
        // Its positive, channel 0: 1000 + 0 + 2 + 0.03.
        assert!((p[27 * c] - 1002.03).abs() < 1e-3, "{}", p[27 * c]);
    }

    #[test]
    fn frame_problems_hold_one_whole_frame() {
        let (b, n, c, f, s) = (2, 3, 2, 4, 2);
        let pos = Tensor::<5>::zeros([b, f, c, s, s], &Device::flex());
        let (g, p) = FieldKind::Frame.problems(tagged(b, n, c, f, s), pos, b);
        assert_eq!((g.dims(), p.dims()), ([b * f, n, c * s * s], [b * f, 1, c * s * s]));
        let g: Vec<f32> = g.into_data().try_into_vec::<f32>().unwrap();
        // Problem (ctx 1, frame 3) = 7, sample 1, element (channel 1, cell 2) = 1·4 + 2 = 6:
        // 1000 + 100 + 10 + 3 + 0.02.
        assert!((g[(7 * n + 1) * c * s * s + 6] - 1113.02).abs() < 1e-3);
    }
}
