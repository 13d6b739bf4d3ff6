//! What an imported diffusion policy ([`crate::imported_policy`]) computes outside its networks,
//! as the PyTorch code it comes from does: torchvision's centre crop and bilinear resize of its
//! frames, and diffusers' DDPM and DDIM sampling of its action sequence.

use burn::tensor::{Tensor, TensorData};

use crate::diffusion::ddim_update;

/// Where a centre crop starts for a `margin` of pixels to drop: torchvision's `CenterCrop`,
/// `round(margin / 2)` with halves to even.
pub fn centre_offset(margin: usize) -> usize {
    if margin % 2 == 1 && (margin / 2) % 2 == 1 { margin / 2 + 1 } else { margin / 2 }
}

/// The weights of PyTorch's bilinear resampling (`align_corners=False`) of `from` samples to
/// `to`: `[to, from]`, each row summing to 1; two taps a row without antialiasing, or the
/// stretched triangle of `antialias=True` ([`harness::resize::torch_aa_taps`]).
pub fn bilinear_weights(from: usize, to: usize, antialias: bool) -> Vec<f32> {
    let mut w = vec![0.0f32; to * from];
    if antialias {
        for (i, (lo, taps)) in harness::resize::torch_aa_taps(from, to).into_iter().enumerate() {
            for (j, v) in taps.into_iter().enumerate() {
                w[i * from + lo + j] += v;
            }
        }
        return w;
    }
    for (i, (i0, i1, l1)) in harness::resize::torch_taps(from, to).into_iter().enumerate() {
        w[i * from + i0] += 1.0 - l1;
        w[i * from + i1] += l1;
    }
    w
}

/// Resizes `[n, c, h, w]` frames to `[n, c, side, side]` with [`bilinear_weights`] along each
/// axis.
pub fn resize_bilinear(x: Tensor<4>, side: usize, antialias: bool) -> Tensor<4> {
    let [n, c, h, w] = x.dims();
    if (h, w) == (side, side) {
        return x;
    }
    let dev = x.device();
    let wy = Tensor::<2>::from_data(TensorData::new(bilinear_weights(h, side, antialias), [side, h]), &dev);
    let wx = Tensor::<2>::from_data(TensorData::new(bilinear_weights(w, side, antialias), [side, w]), &dev);
    let cols = x.matmul(wx.transpose().unsqueeze::<4>().expand([n, c, w, side])); // [n, c, h, side]
    wy.unsqueeze::<4>().expand([n, c, side, h]).matmul(cols) // [n, c, side, side]
}

/// One DDPM step from `x` at step `t` to step `prev` (`None`: the end, ᾱ = 1) given the
/// predicted noise `eps`: the posterior mean of x₀ clipped to [-1, 1], plus `√variance · z`
/// for `t > 0` (`z` standard normal). `ac` is ᾱ over the schedule.
pub fn ddpm_step(x: &mut [f32], eps: &[f32], t: usize, prev: Option<usize>, ac: &[f64], z: &[f32]) {
    let (a, ap) = (ac[t], prev.map_or(1.0, |p| ac[p]));
    let cur = a / ap;
    let (sa, s1a) = (a.sqrt(), (1.0 - a).sqrt());
    let c0 = (ap.sqrt() * (1.0 - cur) / (1.0 - a)) as f32;
    let ct = (cur.sqrt() * (1.0 - ap) / (1.0 - a)) as f32;
    let sd = if t > 0 { ((1.0 - ap) / (1.0 - a) * (1.0 - cur)).max(1e-20).sqrt() as f32 } else { 0.0 };
    for (i, (v, e)) in x.iter_mut().zip(eps).enumerate() {
        let x0 = ((f64::from(*v) - s1a * f64::from(*e)) / sa).clamp(-1.0, 1.0) as f32;
        *v = c0 * x0 + ct * *v + if t > 0 { sd * z[i] } else { 0.0 };
    }
}

/// DDPM sampling of `x` (`[b, horizon, action_dim]`, flat) over `timesteps` (noisiest first)
/// of the schedule `ac`, with the noise predictor `eps(x, t)` and step noise from `noise(len)`.
pub fn ddpm_sample(
    mut x: Vec<f32>,
    ac: &[f64],
    timesteps: &[usize],
    mut eps: impl FnMut(&[f32], usize) -> Vec<f32>,
    mut noise: impl FnMut(usize) -> Vec<f32>,
) -> Vec<f32> {
    for (j, &t) in timesteps.iter().enumerate() {
        let e = eps(&x, t);
        let z = if t > 0 { noise(x.len()) } else { Vec::new() };
        ddpm_step(&mut x, &e, t, timesteps.get(j + 1).copied(), ac, &z);
    }
    x
}

/// DDIM sampling (η = 0) of `x` (`[b, horizon, action_dim]`, flat) over `timesteps` (noisiest
/// first) of the schedule `ac`, with the noise predictor `eps(x, t)`, as diffusers'
/// `DDIMScheduler` steps them ([`ddim_update`], evalharness's own DDIM step), with ᾱ_prev = 1
/// after the last step (`set_alpha_to_one`).
pub fn ddim_sample(
    mut x: Vec<f32>,
    ac: &[f64],
    timesteps: &[usize],
    mut eps: impl FnMut(&[f32], usize) -> Vec<f32>,
) -> Vec<f32> {
    for (j, &t) in timesteps.iter().enumerate() {
        let e = eps(&x, t);
        ddim_update(&mut x, &e, ac[t], timesteps.get(j + 1).map_or(1.0, |&p| ac[p]));
    }
    x
}
