//! Whole-batch CPU kernels of the inference paths that run without burn (the
//! world model's U-Net, the policies' U-Net and encoder): matrix products on the
//! `gemm` crate, dense layers, GroupNorm with a fused activation and per-frame
//! FiLM, and 2-D convolutions as im2col + one product per chunk of images.
//!
//! Activations are channel-major, `[c, n, l]` flattened: channel, then sample,
//! then the sample's `l` positions (frames × pixels for video, time steps for
//! action sequences). A convolution over all samples is then one product
//! `W [c_out, c_in·k] × columns [c_in·k, n·l]`, and concatenating channels is
//! concatenating buffers.

use crate::elementwise::{Norm, exp, mean_var};

/// A matrix view: the slice, and the distance between rows (columns are adjacent).
#[derive(Clone, Copy)]
pub struct View<'a> {
    /// Elements.
    pub data: &'a [f32],
    /// Row stride in elements.
    pub ld: usize,
}

/// A mutable matrix view: the slice, and the distance between rows.
pub struct ViewMut<'a> {
    /// Elements.
    pub data: &'a mut [f32],
    /// Row stride in elements.
    pub ld: usize,
}

/// `c (+)= a · b` for `a: [m, k]`, `b: [k, n]`, `c: [m, n]` with row strides
/// `a.ld`, `b.ld` and `c.ld`, on the `gemm` crate's kernels (the ones burn-flex uses),
/// one thread.
///
/// # Panics
/// If a slice is too short for its shape and stride (a bug in the caller).
pub fn matmul_strided(m: usize, k: usize, n: usize, a: View, b: View, c: ViewMut, accumulate: bool) {
    let (a, b) = (Strided { data: a.data, rs: a.ld, cs: 1 }, Strided { data: b.data, rs: b.ld, cs: 1 });
    matmul_general(m, k, n, a, b, c, accumulate);
}

/// A read-only matrix with both strides: element `(r, c)` at `data[r · rs + c · cs]`
/// (a transposed view is `rs = 1`).
pub struct Strided<'a> {
    /// Elements.
    pub data: &'a [f32],
    /// Row stride in elements.
    pub rs: usize,
    /// Column stride in elements.
    pub cs: usize,
}

/// [`matmul_strided`] with inputs of any strides (`c`'s columns are contiguous).
///
/// # Panics
/// If a slice is too short for its shape and strides (a bug in the caller).
pub fn matmul_general(m: usize, k: usize, n: usize, a: Strided, b: Strided, c: ViewMut, accumulate: bool) {
    let (c, ldc) = (c.data, c.ld);
    let need = |rows: usize, cols: usize, rs: usize, cs: usize| {
        if rows == 0 || cols == 0 { 0 } else { (rows - 1) * rs + (cols - 1) * cs + 1 }
    };
    assert!(
        a.data.len() >= need(m, k, a.rs, a.cs)
            && b.data.len() >= need(k, n, b.rs, b.cs)
            && c.len() >= need(m, n, ldc, 1),
        "matmul shapes"
    );
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            (0..m).for_each(|r| c[r * ldc..r * ldc + n].fill(0.0));
        }
        return;
    }
    // SAFETY: each slice holds every element its shape and strides address (checked
    // above); `c` is borrowed mutably, so it aliases neither input. gemm computes
    // dst := α·dst + β·lhs·rhs.
    #[allow(unsafe_code)]
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            c.as_mut_ptr(),
            1,
            ldc as isize,
            accumulate,
            a.data.as_ptr(),
            a.cs as isize,
            a.rs as isize,
            b.data.as_ptr(),
            b.cs as isize,
            b.rs as isize,
            if accumulate { 1.0 } else { 0.0 },
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

/// `c (+)= a · b` for contiguous row-major `a: [m, k]`, `b: [k, n]`, `c: [m, n]`.
pub fn matmul(m: usize, k: usize, n: usize, a: &[f32], b: &[f32], c: &mut [f32], accumulate: bool) {
    matmul_strided(
        m,
        k,
        n,
        View { data: a, ld: k },
        View { data: b, ld: n },
        ViewMut { data: c, ld: n },
        accumulate,
    );
}

/// `y = x W + b` with burn's layout `W: [d_in, d_out]`.
#[derive(Clone, Debug)]
pub struct Dense {
    din: usize,
    dout: usize,
    w: Vec<f32>,
    b: Vec<f32>,
}

impl Dense {
    /// A layer of `din` inputs and `dout` outputs: `w` in burn's layout `[d_in, d_out]`
    /// (row-major), `b` of `dout`.
    ///
    /// # Panics
    /// When the sizes disagree (a caller's bug, not bad input: callers copy them from
    /// one layer).
    pub fn from_parts(din: usize, dout: usize, w: Vec<f32>, b: Vec<f32>) -> Self {
        assert!(
            w.len() == din * dout && b.len() == dout,
            "dense layer of {din} x {dout}: {} weights, {} biases",
            w.len(),
            b.len()
        );
        Self { din, dout, w, b }
    }

    /// Output size.
    pub fn dout(&self) -> usize {
        self.dout
    }

    /// The layer split by its inputs: the first `at` inputs' rows (no bias) and the
    /// rest's (with the bias), so `x W + b = x[..at] W_a + (x[at..] W_b + b)`.
    pub fn split_inputs(&self, at: usize) -> (Dense, Dense) {
        let at = at.min(self.din);
        let split = at * self.dout;
        let first = Dense { din: at, dout: self.dout, w: self.w[..split].to_vec(), b: vec![0.0; self.dout] };
        let rest =
            Dense { din: self.din - at, dout: self.dout, w: self.w[split..].to_vec(), b: self.b.clone() };
        (first, rest)
    }

    /// `[n, d_in] -> [n, d_out]`
    pub fn forward(&self, x: &[f32]) -> Vec<f32> {
        self.forward_with(x, matmul)
    }

    /// `[n, d_in] -> [n, d_out]` with `product` (`c += a · b`, [`matmul`]'s arguments; the
    /// policies pass `chain_gemm::matmul` for products with the same bits on every CPU).
    pub fn forward_with(&self, x: &[f32], product: Product) -> Vec<f32> {
        let n = x.len() / self.din;
        let mut y: Vec<f32> = (0..n).flat_map(|_| self.b.iter().copied()).collect();
        product(n, self.din, self.dout, x, &self.w, &mut y, true);
        y
    }
}

/// A matrix product with [`matmul`]'s arguments: `(m, k, n, a, b, c, accumulate)`.
pub type Product = fn(usize, usize, usize, &[f32], &[f32], &mut [f32], bool);

/// SiLU with the vectorisable [`exp`].
#[inline(always)]
pub fn silu(x: f32) -> f32 {
    x / (1.0 + exp(-x))
}

/// Per-frame FiLM after a GroupNorm: `y ← y·(1 + scale) + shift`, with `ss`
/// `[n·frames, 2c]` (each row the scales, then the shifts, of one sample's frame).
#[derive(Clone, Copy)]
pub struct Film<'a> {
    /// Scales and shifts.
    pub ss: &'a [f32],
}

/// GroupNorm in place on `x` (`[c, n, frames·plane]`), statistics over each group's
/// channels and all of a sample's positions (biased variance, as burn), then the
/// per-channel affine, the optional per-frame FiLM and `act`, fused in one pass.
pub fn group_norm_cols(
    x: &mut [f32],
    norm: &Norm,
    n: usize,
    frames: usize,
    plane: usize,
    film: Option<Film>,
    act: impl Fn(f32) -> f32 + Copy,
) {
    #[cfg(target_arch = "x86_64")]
    if crate::elementwise::has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above), the
        // requirement of calling a function compiled with those features.
        #[allow(unsafe_code)]
        unsafe {
            group_norm_cols_avx2(x, norm, n, frames, plane, film, act)
        };
        return;
    }
    group_norm_cols_impl(x, norm, n, frames, plane, film, act);
}

/// [`group_norm_cols`] compiled for AVX2 + FMA (its loops vectorise 8 wide).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn group_norm_cols_avx2(
    x: &mut [f32],
    norm: &Norm,
    n: usize,
    frames: usize,
    plane: usize,
    film: Option<Film>,
    act: impl Fn(f32) -> f32 + Copy,
) {
    group_norm_cols_impl(x, norm, n, frames, plane, film, act);
}

/// Statistics by [`mean_var`] over the group's channel rows; then the fused output pass.
#[inline(always)]
fn group_norm_cols_impl(
    x: &mut [f32],
    norm: &Norm,
    n: usize,
    frames: usize,
    plane: usize,
    film: Option<Film>,
    act: impl Fn(f32) -> f32 + Copy,
) {
    let c = norm.gamma.len();
    let l = frames * plane;
    let cols = n * l;
    let per = c / norm.groups;
    let count = (per * l) as f64;
    for g in 0..norm.groups {
        for smp in 0..n {
            let rows = || (g * per..(g + 1) * per).map(|ch| ch * cols + smp * l);
            let (mean, var) = mean_var(|| rows().map(|r| &x[r..r + l]), count);
            let inv = 1.0 / (var + norm.eps).sqrt();
            for (ch, r) in (g * per..).zip(rows()) {
                let a = (inv * f64::from(norm.gamma[ch])) as f32;
                let b = (f64::from(norm.beta[ch]) - mean * inv * f64::from(norm.gamma[ch])) as f32;
                for f in 0..frames {
                    let (a, b) = match film {
                        Some(Film { ss }) => {
                            let row = &ss[(smp * frames + f) * 2 * c..][..2 * c];
                            (a * (1.0 + row[ch]), b * (1.0 + row[ch]) + row[c + ch])
                        }
                        None => (a, b),
                    };
                    x[r + f * plane..r + (f + 1) * plane].iter_mut().for_each(|v| *v = act(*v * a + b));
                }
            }
        }
    }
}

/// Geometry of a 2-D convolution over `imgs` images of `h × w`.
#[derive(Clone, Copy, Debug)]
pub struct Conv2dShape {
    /// Kernel side.
    pub k: usize,
    /// Stride.
    pub stride: usize,
    /// Zero padding on every side.
    pub pad: usize,
}

impl Conv2dShape {
    /// The output side for an input side `s`.
    pub fn out(&self, s: usize) -> usize {
        (s + 2 * self.pad - self.k) / self.stride + 1
    }

    /// im2col of images `i0..i1` of `x` (`[c, imgs, h, w]`) into `col`
    /// (`[c·k·k, (i1 − i0)·h'·w']`).
    #[allow(clippy::too_many_arguments)]
    pub fn im2col(
        &self,
        x: &[f32],
        c: usize,
        imgs: usize,
        h: usize,
        w: usize,
        i0: usize,
        i1: usize,
        col: &mut [f32],
    ) {
        let (ho, wo) = (self.out(h), self.out(w));
        let n = (i1 - i0) * ho * wo;
        let (k, s, p) = (self.k, self.stride, self.pad);
        for ci in 0..c {
            for ky in 0..k {
                for kx in 0..k {
                    let row = &mut col[((ci * k + ky) * k + kx) * n..][..n];
                    for (j, img) in (i0..i1).enumerate() {
                        let plane = &x[(ci * imgs + img) * h * w..][..h * w];
                        let out = &mut row[j * ho * wo..][..ho * wo];
                        // Output columns ox with input column ox·s + kx − p inside [0, w).
                        let ox0 = p.saturating_sub(kx).div_ceil(s).min(wo);
                        let ox1 = (w + p).saturating_sub(kx).div_ceil(s).clamp(ox0, wo);
                        for oy in 0..ho {
                            let dst = &mut out[oy * wo..][..wo];
                            let Some(iy) = (oy * s + ky).checked_sub(p).filter(|&iy| iy < h) else {
                                dst.fill(0.0);
                                continue;
                            };
                            let src = &plane[iy * w..][..w];
                            dst[..ox0].fill(0.0);
                            dst[ox1..].fill(0.0);
                            let first = ox0 * s + kx - p;
                            if s == 1 {
                                dst[ox0..ox1].copy_from_slice(&src[first..first + ox1 - ox0]);
                            } else {
                                for (d, v) in dst[ox0..ox1].iter_mut().zip(src[first..].iter().step_by(s)) {
                                    *d = *v;
                                }
                            }
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strided_product_reads_and_writes_sub_blocks() {
        // a = [[1, 2], [3, 4]] stored with row stride 3 (a padding column of 9s);
        // b = [[5, 6], [7, 8]]; a·b = [[19, 22], [43, 50]] (1·5 + 2·7 = 19, 1·6 + 2·8 = 22,
        // 3·5 + 4·7 = 43, 3·6 + 4·8 = 50), written into columns 1..3 of a 2 × 4 buffer
        // of ones and accumulated onto them.
        let a = [1.0, 2.0, 9.0, 3.0, 4.0, 9.0];
        let b = [5.0, 6.0, 7.0, 8.0];
        let mut c = [1.0f32; 8];
        let out = ViewMut { data: &mut c[1..], ld: 4 };
        matmul_strided(2, 2, 2, View { data: &a, ld: 3 }, View { data: &b, ld: 2 }, out, true);
        assert_eq!(c, [1.0, 20.0, 23.0, 1.0, 1.0, 44.0, 51.0, 1.0]);
    }

    #[test]
    fn group_norm_with_film_by_hand() {
        // One channel, one group, one sample, two frames of two pixels: [0, 2 | 4, 6],
        // mean 3, variance (9 + 1 + 1 + 9) / 4 = 5, so x̂ = (x − 3)/√5 (eps 0).
        // FiLM frame 0: scale 1, shift 0 → 2x̂; frame 1: scale −1, shift 0.5 → 0.5.
        let norm = Norm { groups: 1, gamma: vec![1.0], beta: vec![0.0], eps: 0.0 };
        let mut x = [0.0f32, 2.0, 4.0, 6.0];
        let ss = [1.0, 0.0, -1.0, 0.5];
        group_norm_cols(&mut x, &norm, 1, 2, 2, Some(Film { ss: &ss }), |v| v);
        let r5 = 5f32.sqrt();
        let want = [-6.0 / r5, -2.0 / r5, 0.5, 0.5];
        for (g, w) in x.iter().zip(want) {
            assert!((g - w).abs() < 1e-6, "{x:?} vs {want:?}");
        }
    }

    #[test]
    fn im2col_pads_with_zeros_and_strides() {
        // One 3x3 image 1..9, kernel 3, stride 2, padding 1: a 2x2 output. The centre tap
        // (ky = kx = 1) reads input (2oy, 2ox): 1, 3, 7, 9; the top-left tap reads
        // (2oy − 1, 2ox − 1): only output (1, 1) is inside, reading input (1, 1) = 5.
        let x: Vec<f32> = (1..=9).map(|v| v as f32).collect();
        let shape = Conv2dShape { k: 3, stride: 2, pad: 1 };
        let mut col = vec![f32::NAN; 9 * 4];
        shape.im2col(&x, 1, 1, 3, 3, 0, 1, &mut col);
        assert_eq!(&col[4 * 4..5 * 4], &[1.0, 3.0, 7.0, 9.0]);
        assert_eq!(&col[0..4], &[0.0, 0.0, 0.0, 5.0]);
    }
}
