//! Direct 3x3 convolution, GroupNorm + SiLU and nearest 2x upsampling on the
//! CPU, in plain Rust: the kernels of the world model's decoder (`world_model::cpu_decoder`).
//!
//! Why: `rank` spends about half its CPU time decoding imagined latents, and
//! burn-flex runs every conv2d as an im2col copy plus a small GEMM. This kernel
//! keeps a tile of 4 output channels x 16 pixels in registers across the whole
//! (input channel x tap) reduction, reading each input row straight from a
//! zero-bordered feature map, so nothing is copied and every loaded input value
//! feeds four fused multiply-adds. On x86-64 with AVX2 and FMA (checked at run
//! time) the same code is compiled for those instructions; elsewhere it runs as
//! portable Rust. Only inference uses it (no gradients). Maps of even size go
//! through [`crate::winograd`] instead, which needs fewer multiply-adds.

pub use crate::elementwise::{Norm, exp};
use crate::padded::{LANES, Padded};
use crate::winograd::Winograd3x3;

/// Output channels per tile.
const OUT: usize = 4;

/// A 3x3, stride-1, padding-1 convolution with its weights laid out per tile:
/// `[cout / 4, cin, 9, 4]` (zero-padded to whole tiles of output channels), and in
/// the Winograd domain for maps of even size ([`Winograd3x3`]).
#[derive(Clone, Debug)]
pub struct Conv3x3 {
    cin: usize,
    cout: usize,
    weights: Vec<f32>,
    bias: Vec<f32>,
    winograd: Winograd3x3,
}

/// Whether 3x3 convolutions may use Winograd's algorithm ([`Conv3x3::forward`], the CPU
/// U-Net): yes unless the environment sets `EVALHARNESS_CONV=direct` (read once), to
/// compare with the direct and im2col kernels.
pub fn winograd_enabled() -> bool {
    static ENABLED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *ENABLED.get_or_init(|| std::env::var("EVALHARNESS_CONV").map_or(true, |v| v != "direct"))
}

impl Conv3x3 {
    /// From burn's layout: `weight` `[cout, cin, 3, 3]`, `bias` `[cout]` (zeros when absent).
    pub fn new(cin: usize, cout: usize, weight: &[f32], bias: Option<&[f32]>) -> Self {
        assert_eq!(weight.len(), cout * cin * 9);
        let blocks = cout.div_ceil(OUT);
        let mut weights = vec![0.0; blocks * cin * 9 * OUT];
        for co in 0..cout {
            for ci in 0..cin {
                for tap in 0..9 {
                    weights[((co / OUT * cin + ci) * 9 + tap) * OUT + co % OUT] =
                        weight[(co * cin + ci) * 9 + tap];
                }
            }
        }
        let mut b = vec![0.0; blocks * OUT];
        if let Some(bias) = bias {
            b[..cout].copy_from_slice(bias);
        }
        let winograd = Winograd3x3::new(cin, cout, weight, bias);
        Self { cin, cout, weights, bias: b, winograd }
    }

    /// Input channels.
    pub fn cin(&self) -> usize {
        self.cin
    }

    /// Output channels.
    pub fn cout(&self) -> usize {
        self.cout
    }

    /// Convolves `x` into `out` (`[cout, h, w]`), adding `residual` (same shape) when given:
    /// with [`Winograd3x3`] on maps of even height and width, else directly.
    ///
    /// # Shapes
    /// `x`: `[cin, h, w]` (bordered) -> `out`: `[cout, h, w]`
    pub fn forward(&self, x: &Padded, residual: Option<&[f32]>, out: &mut [f32]) {
        if Winograd3x3::supports(x.height(), x.width()) && winograd_enabled() {
            self.winograd.forward(x, residual, out);
        } else {
            self.forward_direct(x, residual, out);
        }
    }

    /// [`Conv3x3::forward`] with the direct kernel whatever the map's size.
    ///
    /// # Shapes
    /// `x`: `[cin, h, w]` (bordered) -> `out`: `[cout, h, w]`
    pub fn forward_direct(&self, x: &Padded, residual: Option<&[f32]>, out: &mut [f32]) {
        assert_eq!(x.channels(), self.cin);
        assert_eq!(out.len(), self.cout * x.height() * x.width());
        #[cfg(target_arch = "x86_64")]
        if crate::elementwise::has_avx2_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above), the
            // requirement of calling a function compiled with those features.
            #[allow(unsafe_code)]
            unsafe {
                conv_avx2_fma(self, x, residual, out)
            };
            return;
        }
        conv(self, x, residual, out);
    }
}

/// The output tile loop shared by both kernels: for every row, block of 4 output
/// channels and 16-pixel strip, `tile(weights, base, acc)` adds the whole reduction to
/// `acc` (which starts at the bias); `base` is the strip's offset in channel 0's first
/// bordered row. The tile is then written out, plus the residual.
#[inline(always)]
fn each_tile(
    k: &Conv3x3,
    x: &Padded,
    residual: Option<&[f32]>,
    out: &mut [f32],
    mut tile: impl FnMut(&[f32], usize, &mut [[f32; LANES]; OUT]),
) {
    let (h, w, stride) = (x.height(), x.width(), x.stride());
    for y in 0..h {
        for block in 0..k.cout.div_ceil(OUT) {
            let wb = &k.weights[block * k.cin * 9 * OUT..][..k.cin * 9 * OUT];
            let bias = &k.bias[block * OUT..][..OUT];
            for x0 in (0..w).step_by(LANES) {
                let mut acc = [[0.0f32; LANES]; OUT];
                for (a, &b) in acc.iter_mut().zip(bias) {
                    *a = [b; LANES];
                }
                tile(wb, y * stride + x0, &mut acc);
                let n = LANES.min(w - x0);
                for (j, a) in acc.iter().enumerate() {
                    let co = block * OUT + j;
                    if co >= k.cout {
                        break;
                    }
                    let at = (co * h + y) * w + x0;
                    let dst = &mut out[at..at + n];
                    match residual {
                        Some(r) => {
                            for ((d, &s), &r) in dst.iter_mut().zip(a).zip(&r[at..at + n]) {
                                *d = s + r;
                            }
                        }
                        None => dst.copy_from_slice(&a[..n]),
                    }
                }
            }
        }
    }
}

/// The portable kernel: the reduction in plain Rust.
fn conv(k: &Conv3x3, x: &Padded, residual: Option<&[f32]>, out: &mut [f32]) {
    let (data, stride) = (x.data(), x.stride());
    let plane = (x.height() + 2) * stride;
    each_tile(k, x, residual, out, |wb, base, acc| {
        for ci in 0..k.cin {
            let wc = &wb[ci * 9 * OUT..][..9 * OUT];
            for ky in 0..3 {
                let row = &data[ci * plane + ky * stride + base..][..LANES + 2];
                for kx in 0..3 {
                    let wt = &wc[(ky * 3 + kx) * OUT..][..OUT];
                    for (a, &wj) in acc.iter_mut().zip(wt) {
                        for (s, &v) in a.iter_mut().zip(&row[kx..kx + LANES]) {
                            *s += wj * v;
                        }
                    }
                }
            }
        }
    });
}

/// The AVX2 + FMA kernel: the tile's 4 x 16 sums live in eight 8-lane registers
/// through the whole reduction; each tap loads 16 inputs once and feeds 8 fused
/// multiply-adds.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
fn conv_avx2_fma(k: &Conv3x3, x: &Padded, residual: Option<&[f32]>, out: &mut [f32]) {
    use std::arch::x86_64::{__m256, _mm256_fmadd_ps, _mm256_loadu_ps, _mm256_set1_ps, _mm256_storeu_ps};
    let (data, stride) = (x.data(), x.stride());
    let plane = (x.height() + 2) * stride;
    each_tile(k, x, residual, out, |wb, base, acc| {
        let mut r = [[_mm256_set1_ps(0.0); 2]; OUT];
        for (rj, aj) in r.iter_mut().zip(acc.iter()) {
            // SAFETY: `aj` holds 16 floats; unaligned loads are allowed.
            *rj = unsafe { [_mm256_loadu_ps(aj.as_ptr()), _mm256_loadu_ps(aj.as_ptr().add(8))] };
        }
        for ci in 0..k.cin {
            let wc = &wb[ci * 9 * OUT..][..9 * OUT];
            for ky in 0..3 {
                let row = &data[ci * plane + ky * stride + base..][..LANES + 2];
                for kx in 0..3 {
                    // SAFETY: `row` holds LANES + 2 floats (checked by the slice above), so
                    // kx + 16 <= LANES + 2 floats are in bounds for kx <= 2.
                    let (v0, v1): (__m256, __m256) = unsafe {
                        (_mm256_loadu_ps(row.as_ptr().add(kx)), _mm256_loadu_ps(row.as_ptr().add(kx + 8)))
                    };
                    let wt = &wc[(ky * 3 + kx) * OUT..][..OUT];
                    for (rj, &wj) in r.iter_mut().zip(wt) {
                        let wv = _mm256_set1_ps(wj);
                        rj[0] = _mm256_fmadd_ps(wv, v0, rj[0]);
                        rj[1] = _mm256_fmadd_ps(wv, v1, rj[1]);
                    }
                }
            }
        }
        for (rj, aj) in r.iter().zip(acc.iter_mut()) {
            // SAFETY: `aj` holds 16 floats; unaligned stores are allowed.
            unsafe {
                _mm256_storeu_ps(aj.as_mut_ptr(), rj[0]);
                _mm256_storeu_ps(aj.as_mut_ptr().add(8), rj[1]);
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The textbook definition, for comparison.
    fn reference(cin: usize, cout: usize, w: &[f32], b: &[f32], x: &[f32], h: usize, wd: usize) -> Vec<f32> {
        let mut out = vec![0.0; cout * h * wd];
        for co in 0..cout {
            for y in 0..h as isize {
                for xx in 0..wd as isize {
                    let mut s = b[co];
                    for ci in 0..cin {
                        for ky in 0..3isize {
                            for kx in 0..3isize {
                                let (iy, ix) = (y + ky - 1, xx + kx - 1);
                                if iy >= 0 && ix >= 0 && iy < h as isize && ix < wd as isize {
                                    s += w[((co * cin + ci) * 3 + ky as usize) * 3 + kx as usize]
                                        * x[(ci * h + iy as usize) * wd + ix as usize];
                                }
                            }
                        }
                    }
                    out[(co * h + y as usize) * wd + xx as usize] = s;
                }
            }
        }
        out
    }

    use crate::elementwise::test_values as values;

    #[test]
    fn matches_the_definition_on_odd_sizes_and_channel_counts() {
        // 3 output channels (a partial tile), widths below, at and above one 16-pixel tile.
        for (cin, cout, h, w) in [(2, 3, 5, 7), (5, 8, 4, 16), (3, 5, 3, 21), (4, 4, 12, 12)] {
            let wt = values(cout * cin * 9, 7);
            let b = values(cout, 11);
            let x = values(cin * h * w, 3);
            let mut p = Padded::zeros(cin, h, w);
            p.fill(&x, false);
            let k = Conv3x3::new(cin, cout, &wt, Some(&b));
            let mut out = vec![f32::NAN; cout * h * w];
            k.forward_direct(&p, None, &mut out);
            let want = reference(cin, cout, &wt, &b, &x, h, w);
            for (i, (a, e)) in out.iter().zip(&want).enumerate() {
                assert!((a - e).abs() < 1e-4, "{cin}->{cout} {h}x{w} at {i}: {a} vs {e}");
            }
            // The residual is added on the way out.
            k.forward_direct(&p, Some(&want), &mut out);
            assert!(out.iter().zip(&want).all(|(a, e)| (a - 2.0 * e).abs() < 1e-4));
            // The portable kernel (what `forward` runs on CPUs without AVX2 + FMA) agrees.
            let mut portable = vec![f32::NAN; cout * h * w];
            conv(&k, &p, None, &mut portable);
            assert!(portable.iter().zip(&want).all(|(a, e)| (a - e).abs() < 1e-4));
        }
    }
}
