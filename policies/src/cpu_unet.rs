//! The diffusion policy's conditional 1-D U-Net on the CPU without burn: the same
//! network as [`CondUnet1d::forward`], in plain loops over `f32` slices.
//!
//! Why: a decision runs the U-Net once per DDIM step (10 by default) on tensors of
//! a few thousand elements. burn-flex spends most of that time on per-operation
//! overhead (im2col, dispatch, allocation) and on `mish`'s three transcendental
//! calls per element: in `rank` it was ~85% of the policy's time, itself half of
//! the whole run. Here one `mish` is one `exp`, and nothing is dispatched: convolutions are single matrix products over the whole
//! batch (the `gemm` crate's kernels), and the FiLM layers' observation half is
//! computed once per decision instead of once per step. A [`DiffusionPolicy`](crate::diffusion::DiffusionPolicy)
//! on the Flex device samples with this; training keeps burn's path. The two agree
//! to float rounding (tested below).
//!
//! Inside, sequences are `[c, n·t]` (channel-major, then sample, then position);
//! the public interface takes burn's row-major `[n, horizon, action_dim]`.

use burn::nn::conv::{Conv1d, ConvTranspose1d};
use burn::nn::{GroupNorm, Linear, PaddingConfig1d};

use kernels::direct_conv::Norm;
use kernels::matrix::{Dense, Product, group_norm_cols};
use nn::weights::{bias_values, dense_of, norm_of, values};

use crate::net::{CondRes1d, CondUnet1d, Conv1dBlock, Level1d};

/// Which kernels run a U-Net's matrix products. Policy actions feed back into their MuJoCo
/// episodes, so this decides the MuJoCo branch's rows bit for bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Products {
    /// The `gemm` crate's AVX2 kernels: the same bits on every x86-64 CPU with AVX2 and FMA, the
    /// bits the shipped policies' recorded rows were made with (their default).
    GemmCrate,
    /// [`kernels::chain_gemm`]: one FMA chain per element, the same bits on every CPU, with
    /// AVX-512 where the CPU has it (the imported policies' default: about 1.5× the `gemm`
    /// crate's speed on their large U-Nets).
    Chain,
}

/// Chooses [`Products`] for every policy: `crate` or `chain`.
pub const POLICY_GEMM_ENV: &str = "EVALHARNESS_POLICY_GEMM";

impl Products {
    /// [`POLICY_GEMM_ENV`]'s choice if it makes one, else `default` (read once; any other value
    /// is warned about and ignored).
    pub fn or_env(default: Self) -> Self {
        static CHOICE: std::sync::OnceLock<Option<Products>> = std::sync::OnceLock::new();
        let choice = CHOICE.get_or_init(|| match std::env::var(POLICY_GEMM_ENV).as_deref().map(str::trim) {
            Ok("crate") => Some(Self::GemmCrate),
            Ok("chain") => Some(Self::Chain),
            Ok(other) => {
                tracing::warn!("{POLICY_GEMM_ENV}={other:?} ignored: it takes `crate` or `chain`");
                None
            }
            Err(_) => None,
        });
        choice.unwrap_or(default)
    }

    /// These kernels' matrix product (`c += a · b`, [`kernels::matrix::matmul`]'s arguments).
    fn product(self) -> Product {
        match self {
            Self::GemmCrate => kernels::matrix::matmul,
            Self::Chain => kernels::chain_gemm::matmul,
        }
    }

    /// `c (+)= a · b` (`a: [m, k]`, `b: [k, n]`, `c: [m, n]`, row-major) on these kernels.
    pub(crate) fn matmul(
        self,
        (m, k, n): (usize, usize, usize),
        a: &[f32],
        b: &[f32],
        c: &mut [f32],
        accumulate: bool,
    ) {
        self.product()(m, k, n, a, b, c, accumulate);
    }

    /// A dense layer's `[n, d_in] -> [n, d_out]` on these kernels.
    fn dense(self, d: &Dense, x: &[f32]) -> Vec<f32> {
        d.forward_with(x, self.product())
    }
}

/// Why a U-Net cannot be run by these kernels (a layer they do not support).
#[derive(Debug, thiserror::Error)]
#[error("policy U-Net {0}")]
pub struct UnsupportedLayer(#[from] nn::UnsupportedLayer);

fn unsupported(layer: &str, message: impl Into<String>) -> UnsupportedLayer {
    UnsupportedLayer(nn::UnsupportedLayer::new(layer, message))
}

/// A dense layer, its errors named for this network.
fn dense(l: &Linear, layer: &str) -> Result<Dense, UnsupportedLayer> {
    Ok(dense_of(l, layer)?)
}

/// Mish, `x · tanh(softplus(x))`, with one (polynomial) `exp`: tanh(ln(1 + e)) = n / (n + 2) for
/// n = e(e + 2). Above 20 softplus is the identity (burn's threshold) and so is mish.
fn mish(x: f32) -> f32 {
    if x > 20.0 {
        return x;
    }
    let e = kernels::direct_conv::exp(x);
    let n = e * (e + 2.0);
    x * n / (n + 2.0)
}

/// A 1-D convolution (dilation 1, one group), weights `[c_out, c_in·k]`, run as one
/// matrix product over the whole batch: activations are `[c, n·t]` (channel-major,
/// then sample, then position).
#[derive(Clone, Debug)]
struct Conv1 {
    cin: usize,
    cout: usize,
    k: usize,
    stride: usize,
    pad: usize,
    w: Vec<f32>,
    b: Vec<f32>,
}

impl Conv1 {
    fn new(c: &Conv1d, layer: &str) -> Result<Self, UnsupportedLayer> {
        let pad = match c.padding {
            PaddingConfig1d::Explicit(a, b) if a == b => a,
            PaddingConfig1d::Valid => 0,
            ref p => return Err(unsupported(layer, format!("padding {p:?}"))),
        };
        if c.dilation != 1 || c.groups != 1 {
            return Err(unsupported(layer, "only dilation 1 and one group are supported"));
        }
        let w = c.weight.val();
        let [cout, cin, k] = w.dims();
        Ok(Self {
            cin,
            cout,
            k,
            stride: c.stride,
            pad,
            w: values(w, layer)?,
            b: bias_values(&c.bias, cout, layer)?,
        })
    }

    /// `[c_in, n·t] -> [c_out, n·t']`, returning t'.
    fn forward(&self, pr: Products, x: &[f32], n: usize, t: usize) -> (Vec<f32>, usize) {
        let (s, p, k) = (self.stride, self.pad, self.k);
        let to = (t + 2 * p).saturating_sub(k) / s + 1;
        let cols = n * to;
        let mut y: Vec<f32> = self.b.iter().flat_map(|&b| std::iter::repeat_n(b, cols)).collect();
        if k == 1 && s == 1 && p == 0 {
            pr.matmul((self.cout, self.cin, cols), &self.w, x, &mut y, true);
            return (y, to);
        }
        // im2col: row (ci, kk), column (sample, o) holds x[ci, sample, o·s + kk − p].
        let mut col = vec![0.0; self.cin * k * cols];
        for ci in 0..self.cin {
            for kk in 0..k {
                let row = &mut col[(ci * k + kk) * cols..][..cols];
                let lo = p.saturating_sub(kk).div_ceil(s);
                let hi = (t + p).saturating_sub(kk).div_ceil(s).min(to);
                for smp in 0..n {
                    let xr = &x[ci * n * t + smp * t..][..t];
                    for o in lo..hi {
                        row[smp * to + o] = xr[o * s + kk - p];
                    }
                }
            }
        }
        pr.matmul((self.cout, self.cin * k, cols), &self.w, &col, &mut y, true);
        (y, to)
    }
}

/// A transposed 1-D convolution (dilation 1, one group): one matrix product to
/// per-tap contributions `[c_out·k, n·t]`, then scattered to their output positions.
#[derive(Clone, Debug)]
struct ConvT1 {
    cin: usize,
    cout: usize,
    k: usize,
    stride: usize,
    pad: usize,
    pad_out: usize,
    /// `[c_out·k, c_in]` (burn stores `[c_in, c_out, k]`).
    w: Vec<f32>,
    b: Vec<f32>,
}

impl ConvT1 {
    fn new(c: &ConvTranspose1d, layer: &str) -> Result<Self, UnsupportedLayer> {
        if c.dilation != 1 || c.groups != 1 {
            return Err(unsupported(layer, "only dilation 1 and one group are supported"));
        }
        let w = c.weight.val();
        let [cin, cout, k] = w.dims();
        let w = values(w.reshape([cin, cout * k]).transpose(), layer)?;
        let (stride, pad, pad_out) = (c.stride, c.padding, c.padding_out);
        Ok(Self { cin, cout, k, stride, pad, pad_out, w, b: bias_values(&c.bias, cout, layer)? })
    }

    /// `[c_in, n·t] -> [c_out, n·t']` with t' = (t − 1)·s − 2p + k + p_out, returning t'.
    fn forward(&self, pr: Products, x: &[f32], n: usize, t: usize) -> (Vec<f32>, usize) {
        let (s, p, k) = (self.stride, self.pad, self.k);
        let to = ((t - 1) * s + k + self.pad_out).saturating_sub(2 * p);
        let mut z = vec![0.0; self.cout * k * n * t];
        pr.matmul((self.cout * k, self.cin, n * t), &self.w, x, &mut z, false);
        let mut y: Vec<f32> = self.b.iter().flat_map(|&b| std::iter::repeat_n(b, n * to)).collect();
        for co in 0..self.cout {
            let yr = &mut y[co * n * to..][..n * to];
            for kk in 0..k {
                let zr = &z[(co * k + kk) * n * t..][..n * t];
                for smp in 0..n {
                    for i in 0..t {
                        let o = i * s + kk;
                        if o >= p && o - p < to {
                            yr[smp * to + o - p] += zr[smp * t + i];
                        }
                    }
                }
            }
        }
        (y, to)
    }
}

/// GroupNorm followed by mish, in place on `[c, n·t]`.
#[derive(Clone, Debug)]
struct NormMish(Norm);

impl NormMish {
    fn new(g: &GroupNorm, layer: &str) -> Result<Self, UnsupportedLayer> {
        Ok(Self(norm_of(g, layer)?))
    }

    fn apply(&self, x: &mut [f32], n: usize, t: usize) {
        group_norm_cols(x, &self.0, n, 1, t, None, mish);
    }
}

/// Conv → GroupNorm → mish ([`Conv1dBlock`]).
#[derive(Clone, Debug)]
struct Block {
    conv: Conv1,
    norm: NormMish,
}

impl Block {
    fn new(b: &Conv1dBlock, layer: &str) -> Result<Self, UnsupportedLayer> {
        Ok(Self { conv: Conv1::new(&b.conv, layer)?, norm: NormMish::new(&b.norm, layer)? })
    }

    fn forward(&self, pr: Products, x: &[f32], n: usize, t: usize) -> Vec<f32> {
        let (mut y, to) = self.conv.forward(pr, x, n, t);
        self.norm.apply(&mut y, n, to);
        y
    }
}

/// Block, FiLM from the conditioning, block, plus a skip ([`CondRes1d`]). The FiLM
/// layer is split by its input: the step-embedding rows change every DDIM step, the
/// observation rows only every decision ([`CpuUnet1d::prepare`]).
#[derive(Clone, Debug)]
struct Res {
    b0: Block,
    /// FiLM rows of the step embedding: `[e, 2·c_out]`, no bias.
    film_step: Dense,
    /// FiLM rows of the observation, with the bias: `[obs, 2·c_out]`.
    film_obs: Dense,
    b1: Block,
    skip: Option<Conv1>,
}

impl Res {
    fn new(r: &CondRes1d, step_embed: usize, layer: &str) -> Result<Self, UnsupportedLayer> {
        let (film_step, film_obs) = dense(&r.film, &format!("{layer}.film"))?.split_inputs(step_embed);
        Ok(Self {
            b0: Block::new(&r.b0, &format!("{layer}.b0"))?,
            film_step,
            film_obs,
            b1: Block::new(&r.b1, &format!("{layer}.b1"))?,
            skip: r.skip.as_ref().map(|s| Conv1::new(s, &format!("{layer}.skip"))).transpose()?,
        })
    }

    /// `x: [c_in, n·t]`; `film_obs: [n, 2·c_out]`, `film_step: [2·c_out]` → `[c_out, n·t]`
    fn forward(&self, pr: Products, x: &[f32], (n, t): (usize, usize), film: (&[f32], &[f32])) -> Vec<f32> {
        let (film_obs, film_step) = film;
        let mut h = self.b0.forward(pr, x, n, t); // [co, n t]
        let co = self.b0.conv.cout;
        for (c, rows) in h.chunks_mut(n * t).enumerate() {
            for (smp, row) in rows.chunks_mut(t).enumerate() {
                let f = &film_obs[smp * 2 * co..];
                let (scale, shift) = (f[c] + film_step[c], f[co + c] + film_step[co + c]);
                row.iter_mut().for_each(|v| *v = *v * scale + shift);
            }
        }
        let mut h = self.b1.forward(pr, &h, n, t);
        match &self.skip {
            Some(s) => h.iter_mut().zip(s.forward(pr, x, n, t).0).for_each(|(a, b)| *a += b),
            None => h.iter_mut().zip(x).for_each(|(a, b)| *a += b),
        }
        h
    }
}

/// Two conditional blocks and an optional resampling ([`Level1d`]).
#[derive(Clone, Debug)]
struct Level {
    r0: Res,
    r1: Res,
    down: Option<Conv1>,
    up: Option<ConvT1>,
}

impl Level {
    fn new(l: &Level1d, e: usize, layer: &str) -> Result<Self, UnsupportedLayer> {
        Ok(Self {
            r0: Res::new(&l.r0, e, &format!("{layer}.r0"))?,
            r1: Res::new(&l.r1, e, &format!("{layer}.r1"))?,
            down: l.down.as_ref().map(|d| Conv1::new(d, &format!("{layer}.down"))).transpose()?,
            up: l.up.as_ref().map(|u| ConvT1::new(u, &format!("{layer}.up"))).transpose()?,
        })
    }
}

/// The U-Net's weights, laid out for these kernels.
#[derive(Clone, Debug)]
pub struct CpuUnet1d {
    step1: Dense,
    step2: Dense,
    step_embed: usize,
    downs: Vec<Level>,
    mids: Vec<Res>,
    ups: Vec<Level>,
    final_block: Block,
    final_conv: Conv1,
    products: Products,
}

/// What a decision's observations contribute to every FiLM layer (`[n, 2·c_out]` each,
/// in [`CpuUnet1d::blocks`] order); the same for all of its DDIM steps.
pub struct Prepared {
    n: usize,
    film_obs: Vec<Vec<f32>>,
}

impl CpuUnet1d {
    /// Copies `u`'s weights; its products will run on `products`' kernels.
    ///
    /// # Errors
    /// [`UnsupportedLayer`] for a layer these kernels do not run (grouped or dilated
    /// convolutions, asymmetric padding) or weights that are not f32.
    pub fn new(u: &CondUnet1d, products: Products) -> Result<Self, UnsupportedLayer> {
        let e = u.step_embed;
        let levels = |ls: &[Level1d], name: &str| -> Result<Vec<Level>, UnsupportedLayer> {
            ls.iter().enumerate().map(|(i, l)| Level::new(l, e, &format!("{name}.{i}"))).collect()
        };
        let mids = u.mids.iter().enumerate().map(|(i, m)| Res::new(m, e, &format!("mids.{i}")));
        Ok(Self {
            step1: dense(&u.step1, "step1")?,
            step2: dense(&u.step2, "step2")?,
            step_embed: e,
            downs: levels(&u.downs, "downs")?,
            mids: mids.collect::<Result<_, _>>()?,
            ups: levels(&u.ups, "ups")?,
            final_block: Block::new(&u.final_block, "final_block")?,
            final_conv: Conv1::new(&u.final_conv, "final_conv")?,
            products,
        })
    }

    /// The conditional blocks in the order `forward` runs them.
    fn blocks(&self) -> Vec<&Res> {
        let mut v: Vec<&Res> = self.downs.iter().flat_map(|l| [&l.r0, &l.r1]).collect();
        v.extend(&self.mids);
        v.extend(self.ups.iter().flat_map(|l| [&l.r0, &l.r1]));
        v
    }

    /// The observation part of every FiLM layer for `obs: [n, obs_cond]`.
    pub fn prepare(&self, obs: &[f32], n: usize) -> Prepared {
        let m: Vec<f32> = obs.iter().map(|&v| mish(v)).collect();
        Prepared { n, film_obs: self.blocks().iter().map(|r| self.products.dense(&r.film_obs, &m)).collect() }
    }

    /// Predicts the noise of the prepared decision's `n` noisy action sequences at
    /// diffusion step `t`.
    ///
    /// # Shapes
    /// - `x`: `[n, horizon, action_dim]`
    /// - returns `[n, horizon, action_dim]`
    pub fn forward(&self, prep: &Prepared, x: &[f32], horizon: usize, t: f32) -> Vec<f32> {
        let (n, a, pr) = (prep.n, self.final_conv.cout, self.products);
        // Step embedding (as `net::sinusoidal`) and its MLP: the same for every sample.
        let half = self.step_embed / 2;
        let args: Vec<f32> =
            (0..half).map(|i| t * (-(10000f32).ln() * i as f32 / (half - 1).max(1) as f32).exp()).collect();
        let emb: Vec<f32> = args.iter().map(|v| v.sin()).chain(args.iter().map(|v| v.cos())).collect();
        let mut h1 = pr.dense(&self.step1, &emb);
        h1.iter_mut().for_each(|v| *v = mish(*v));
        let te: Vec<f32> = pr.dense(&self.step2, &h1).into_iter().map(mish).collect(); // mish(te): [e]
        let blocks = self.blocks();
        let film_step: Vec<Vec<f32>> = blocks.iter().map(|r| pr.dense(&r.film_step, &te)).collect();
        let mut film = prep.film_obs.iter().zip(&film_step);
        let mut res = |r: &Res, h: &[f32], len: usize| {
            let (fo, fs) = film.next().unwrap_or_else(|| unreachable!("one FiLM per block"));
            r.forward(pr, h, (n, len), (fo, fs))
        };
        // [n, horizon, a] -> [a, n·horizon]
        let mut h = vec![0.0; n * horizon * a];
        for smp in 0..n {
            for s in 0..horizon {
                for c in 0..a {
                    h[c * n * horizon + smp * horizon + s] = x[(smp * horizon + s) * a + c];
                }
            }
        }
        let mut len = horizon;
        let mut skips = Vec::new();
        for l in &self.downs {
            h = res(&l.r0, &h, len);
            h = res(&l.r1, &h, len);
            skips.push(h.clone());
            if let Some(d) = &l.down {
                (h, len) = d.forward(pr, &h, n, len);
            }
        }
        for m in &self.mids {
            h = res(m, &h, len);
        }
        for l in &self.ups {
            let skip = skips.pop().unwrap_or_else(|| h.clone());
            h.extend_from_slice(&skip); // channel concatenation: [c_h + c_skip, n·len]
            h = res(&l.r0, &h, len);
            h = res(&l.r1, &h, len);
            if let Some(u) = &l.up {
                (h, len) = u.forward(pr, &h, n, len);
            }
        }
        let (y, len) = self.final_conv.forward(pr, &self.final_block.forward(pr, &h, n, len), n, len);
        let mut out = vec![0.0; n * len * a];
        for smp in 0..n {
            for s in 0..len {
                for c in 0..a {
                    out[(smp * len + s) * a + c] = y[c * n * len + smp * len + s];
                }
            }
        }
        out
    }
}

#[cfg(test)]
#[path = "cpu_unet_tests.rs"]
mod tests;
