//! The drifting loss of DriftWorld (spec §2): a one-step generator is trained
//! by moving each generated sample along a *drift field* that attracts it to the
//! positives and repels it from the negatives (the other generated samples and,
//! optionally, weighted fixed negatives).
//!
//! This is the batch-independent form used by the authors for Push-T: scale,
//! temperature normalisation and the loss are computed per batch element `b`.
//! Everything except the final regression is computed without gradient.
//!
//! # Shapes
//! - generated `x`: `[b, g, s]` (g samples of dimension s per element)
//! - negatives `y_neg`: `[b, n, s]` with weights `[b, n]` (n may be 0)
//! - positives `y_pos`: `[b, p, s]` (weight 1 each)

use burn::tensor::activation::softmax;
use burn::tensor::{Device, Tensor, TensorData};

/// The drift temperatures of the Push-T configuration.
pub const PUSHT_TEMPERATURES: [f32; 3] = [0.02, 0.05, 0.2];

/// The field, its scale and the per-temperature diagnostics of one loss call.
#[derive(Clone, Debug)]
pub struct DriftField {
    /// The summed, per-temperature RMS-normalised field in scaled units, `[b, g, s]`.
    pub v: Tensor<3>,
    /// Per-element feature scale σ, `[b, 1, 1]`.
    pub sigma: Tensor<3>,
    /// `mean V_R²` before normalisation, per temperature, averaged over elements:
    /// the meaningful progress metric (the regression loss is ≈ constant).
    pub loss_r: Vec<f32>,
}

/// Fixed negatives and their weights.
#[derive(Clone, Debug)]
pub struct Negatives {
    /// `[b, n, s]`
    pub y: Tensor<3>,
    /// `[b, n]`
    pub w: Tensor<2>,
}

/// Computes the drift field of `x` (no gradient flows through it).
pub fn drift_field(x: &Tensor<3>, neg: Option<&Negatives>, y_pos: &Tensor<3>, temps: &[f32]) -> DriftField {
    let device = x.device();
    let [b, g, s] = x.dims();
    let [_, p, _] = y_pos.dims();
    let x = x.clone().detach();
    let ones = |n: usize| Tensor::<2>::ones([b, n], &device);
    let (y, w, n) = match neg {
        Some(ng) => {
            let [_, n, _] = ng.y.dims();
            let y = Tensor::cat(vec![x.clone(), ng.y.clone().detach(), y_pos.clone().detach()], 1);
            let w = Tensor::cat(vec![ones(g), ng.w.clone().detach(), ones(p)], 1);
            (y, w, n)
        }
        None => (Tensor::cat(vec![x.clone(), y_pos.clone().detach()], 1), ones(g + p), 0),
    };
    let m = g + n + p;
    // d_ij = sqrt(max(|x_i|² + |y_j|² - 2 x_i·y_j, 1e-8))                  // [b, g, m]
    let xx = x.clone().powf_scalar(2.0).sum_dim(2); // [b, g, 1]
    let yy = y.clone().powf_scalar(2.0).sum_dim(2).swap_dims(1, 2); // [b, 1, m]
    let xy = x.clone().matmul(y.clone().swap_dims(1, 2)); // [b, g, m]
    let d = (xx + yy - xy * 2.0).clamp_min(1e-8).sqrt();
    // s = Σ_ij w_j d_ij / (g Σ_j w_j): the weighted mean distance, self included.
    let w3 = w.clone().unsqueeze_dim::<3>(1); // [b, 1, m]
    let wsum = w.sum_dim(1).unsqueeze_dim::<3>(2); // [b, 1, 1]
    let scale = (d.clone() * w3.clone()).sum_dim(2).sum_dim(1) / (wsum * g as f64); // [b, 1, 1]
    let sigma = (scale.clone() / (s as f64).sqrt()).clamp_min(1e-3); // [b, 1, 1]
    let x_t = x / sigma.clone(); // [b, g, s]
    let y_t = y / sigma.clone(); // [b, m, s]
    let mut d_hat = d / scale.clamp_min(1e-3); // [b, g, m]
    // Exclude each sample from its own negatives: d̂_ii = 1e6.
    let self_mask = self_mask(g, m, &device); // [1, g, m] bool
    d_hat = d_hat.mask_fill(self_mask.expand([b, g, m]), 1e6);
    let split = g + n;
    let y_neg_t = y_t.clone().narrow(1, 0, split); // [b, g+n, s]
    let y_pos_t = y_t.narrow(1, split, p); // [b, p, s]
    let mut v = Tensor::<3>::zeros([b, g, s], &device);
    let mut loss_r = Vec::with_capacity(temps.len());
    for &r in temps {
        let logits = d_hat.clone() / (-(r as f64)); // [b, g, m]
        let p_row = softmax(logits.clone(), 2);
        let p_col = softmax(logits, 1);
        let a = (p_row * p_col).clamp_min(1e-6).sqrt() * w3.clone(); // [b, g, m]
        let a_neg = a.clone().narrow(2, 0, split); // [b, g, g+n]
        let a_pos = a.narrow(2, split, p); // [b, g, p]
        let s_pos = a_pos.clone().sum_dim(2); // [b, g, 1]
        let s_neg = a_neg.clone().sum_dim(2); // [b, g, 1]
        // V_i = S⁻_i Σ_p A_ip ỹ_p − S⁺_i Σ_j A_ij ỹ_j − c_i x̃_i, c_i = S⁻S⁺ − S⁺S⁻ (≈ 0).
        let c = s_neg.clone() * s_pos.clone() - s_pos.clone() * s_neg.clone();
        let v_r =
            a_pos.matmul(y_pos_t.clone()) * s_neg - a_neg.matmul(y_neg_t.clone()) * s_pos - x_t.clone() * c; // [b, g, s]
        let ms = v_r.clone().powf_scalar(2.0).mean_dims(&[1, 2]); // [b, 1, 1]
        loss_r.push(ms.clone().mean().into_scalar::<f32>());
        let lambda = ms.clamp_min(1e-8).sqrt();
        v = v + v_r / lambda;
    }
    DriftField { v, sigma, loss_r }
}

/// The drifting loss: `mean_b mean_{i,d} (x_i/σ − sg(x̃_i + V_i))²`, with the field's diagnostics.
///
/// The gradient is `∂L/∂x_i = −2 V_i / (b g s σ)`: the samples move along the field.
pub fn drift_loss(
    x: Tensor<3>,
    neg: Option<&Negatives>,
    y_pos: &Tensor<3>,
    temps: &[f32],
) -> (Tensor<1>, DriftField) {
    drift_loss_weighted(x, neg, y_pos, temps, None)
}

/// [`drift_loss`] with a weight per problem `b` (`[b]`, e.g. motion weighting, spec
/// §4): `mean_b w_b · mean_{i,d} (x_i/σ − sg(x̃_i + V_i))²`. The field is unchanged.
pub fn drift_loss_weighted(
    x: Tensor<3>,
    neg: Option<&Negatives>,
    y_pos: &Tensor<3>,
    temps: &[f32],
    weights: Option<Tensor<1>>,
) -> (Tensor<1>, DriftField) {
    let field = drift_field(&x, neg, y_pos, temps);
    let x_scaled = x / field.sigma.clone().detach(); // [b, g, s]
    let goal = (x_scaled.clone().detach() + field.v.clone()).detach();
    let per = (x_scaled - goal).powf_scalar(2.0); // [b, g, s]
    let loss = match weights {
        Some(w) => {
            let [b, _, _] = per.dims();
            (per.mean_dims(&[1, 2]).reshape([b]) * w.detach()).mean()
        }
        None => per.mean(),
    };
    (loss, field)
}

/// `[1, g, m]` mask, true at (i, i) for i < g.
fn self_mask(g: usize, m: usize, device: &Device) -> Tensor<3, burn::tensor::Bool> {
    let mut data = vec![false; g * m];
    for i in 0..g {
        data[i * m + i] = true;
    }
    Tensor::from_data(TensorData::new(data, [1, g, m]), device)
}

#[cfg(test)]
mod tests;
