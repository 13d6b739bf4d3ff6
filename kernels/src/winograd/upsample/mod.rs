//! Nearest 2x upsampling followed by a 3x3 convolution, computed on the small map
//! with Winograd F(2x2, 2x2): the frame decoder's `dec_up` layers.
//!
//! Why: on a nearest-upsampled map every 3x3 window covers only 2x2 distinct input
//! pixels, so the layer is four 2x2 convolutions of the small map, one per output
//! phase (row and column parity), with the 3x3 taps summed into 2x2: an even output
//! row `2i` sees input row `i − 1` through tap row 0 and row `i` through tap rows 1
//! and 2; an odd row `2i + 1` sees row `i` through tap rows 0 and 1 and row `i + 1`
//! through tap row 2 (columns alike). Each phase runs as Winograd's F(2x2, 2x2): a
//! 3x3 input tile, transformed with `Bᵀ = [[1, −1, 0], [0, 1, 0], [0, −1, 1]]`, 9
//! products per 2x2 outputs and channel pair (the F(2x2, 3x3) kernel of
//! [`super::Winograd3x3`] spends 16 per 2x2 outputs on the upsampled map), and
//! `Aᵀ = [[1, 1, 0], [0, 1, 1]]` back. Input transforms run on a map a quarter the
//! size, and the upsampled map is never built. The transforms use only 0 and ±1,
//! so the result equals upsampling then convolving to float rounding (tested below).

#[cfg(target_arch = "x86_64")]
mod avx2;

use super::{LANES, OUT, TILES_PER_PASS, Winograd3x3, bias_or_zeros, pack_filters, products};
use crate::padded::Padded;

/// Tap rows (or columns) of the 3x3 filter that reach the phase's input row `r` (0:
/// the upper of its two rows, 1: the lower), for output rows of parity `a`:
/// `TAPS[a][r]`.
const TAPS: [[&[usize]; 2]; 2] = [[&[0], &[1, 2]], [&[0, 1], &[2]]];

/// F(2x2, 2x2)'s filter transform `G` (3x2).
const G: [[f64; 2]; 3] = [[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];

/// A 3x3 convolution of a nearest-2x-upsampled map, per output phase in the Winograd
/// domain: `u[a · 2 + b]` is `[9, cout / 4, cin, 4]` for output rows of parity `a` and
/// columns of parity `b` (zero-padded to whole blocks of output channels).
#[derive(Clone, Debug)]
pub struct Upsample3x3 {
    cin: usize,
    cout: usize,
    u: [Vec<f32>; 4],
    bias: Vec<f32>,
}

/// The 2x2 filter of phase `(a, b)`: the 3x3 taps `w` (`[ky, kx]`) summed per
/// [`TAPS`], as `[ry · 2 + rx]`, in f64.
fn phase_filter(w: &[f32], a: usize, b: usize) -> [f64; 4] {
    std::array::from_fn(|p| {
        let (ry, rx) = (p / 2, p % 2);
        let mut s = 0.0;
        for &ky in TAPS[a][ry] {
            for &kx in TAPS[b][rx] {
                s += f64::from(w[ky * 3 + kx]);
            }
        }
        s
    })
}

/// `G g Gᵀ` of one 2x2 filter, as `[i · 3 + j]`.
fn transform_filter(g: &[f64; 4]) -> [f32; 9] {
    std::array::from_fn(|p| {
        let (gi, gj) = (&G[p / 3], &G[p % 3]);
        let mut s = 0.0;
        for (r, &x) in gi.iter().enumerate() {
            for (c, &y) in gj.iter().enumerate() {
                s += x * g[r * 2 + c] * y;
            }
        }
        s as f32
    })
}

impl Upsample3x3 {
    /// From burn's layout: `weight` `[cout, cin, 3, 3]`, `bias` `[cout]` (zeros when absent).
    pub fn new(cin: usize, cout: usize, weight: &[f32], bias: Option<&[f32]>) -> Self {
        assert_eq!(weight.len(), cout * cin * 9);
        let u = std::array::from_fn(|phase| {
            pack_filters(cin, cout, |co, ci| {
                transform_filter(&phase_filter(&weight[(co * cin + ci) * 9..][..9], phase / 2, phase % 2))
            })
        });
        Self { cin, cout, u, bias: bias_or_zeros(cout, bias) }
    }

    /// Whether an `h` x `w` input map can be upsampled and convolved this way (whole
    /// 2x2 tiles of each phase).
    pub fn supports(h: usize, w: usize) -> bool {
        Winograd3x3::supports(h, w)
    }

    /// Upsamples `x` 2x (nearest) and convolves it into `out`.
    ///
    /// # Shapes
    /// `x`: `[cin, h, w]` (bordered) -> `out`: `[cout, 2h, 2w]`
    pub fn forward(&self, x: &Padded, out: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        if crate::elementwise::has_avx2_fma() {
            return self.run(x, out, true);
        }
        self.run(x, out, false);
    }

    /// Tile rows in passes of about [`TILES_PER_PASS`] tiles: for each output row
    /// parity, both column phases' input transforms and products, then their outputs
    /// interleaved. `simd`: the AVX2 transforms (only when the CPU has them).
    fn run(&self, x: &Padded, out: &mut [f32], simd: bool) {
        let (h, w) = (x.height(), x.width());
        assert!(Self::supports(h, w), "upsampling convolution of a {h}x{w} map (needs even sides)");
        assert_eq!(x.channels(), self.cin);
        assert_eq!(out.len(), self.cout * 4 * h * w);
        let (th, tw) = (h / 2, w / 2);
        let rows = (TILES_PER_PASS / tw).clamp(1, th);
        let nk = (rows * tw).div_ceil(LANES) * LANES;
        let cout4 = self.cout.div_ceil(OUT) * OUT;
        // Kept per thread. Values left from an earlier pass or call only ever meet tiles
        // that are never written out.
        let [mut v0, mut v1, mut m0, mut m1] = BUFFERS.take();
        for vb in [&mut v0, &mut v1] {
            vb.resize(self.cin * 9 * nk, 0.0);
        }
        // One run of 8 more: a row's last, partial run of tiles is loaded whole.
        for mb in [&mut m0, &mut m1] {
            mb.resize(cout4 * 9 * nk + LANES, 0.0);
        }
        let (mut v, mut m) = ([v0, v1], [m0, m1]);
        for a in 0..2 {
            for ty0 in (0..th).step_by(rows) {
                let n = rows.min(th - ty0);
                for (b, (vb, mb)) in v.iter_mut().zip(&mut m).enumerate() {
                    let at = Tiles { nk, tw, a, b };
                    for r in 0..n {
                        transform_input(x, &at, ty0 + r, vb, r * tw, simd);
                    }
                    products(&self.u[a * 2 + b], self.cin, 9, vb, mb, nk);
                }
                let pass = Pass { nk, tw, a, ty0, rows: n, h2: 2 * h, w2: 2 * w };
                transform_output(self, &m, &pass, out, simd);
            }
        }
        let ([v0, v1], [m0, m1]) = (v, m);
        BUFFERS.set([v0, v1, m0, m1]);
    }
}

thread_local! {
    /// This thread's transformed inputs and products (`v` and `m` of [`Upsample3x3::run`],
    /// one pair per column phase), kept from call to call instead of allocated zeroed
    /// for every upsampling layer of every frame.
    static BUFFERS: std::cell::Cell<[Vec<f32>; 4]> =
        const { std::cell::Cell::new([Vec::new(), Vec::new(), Vec::new(), Vec::new()]) };
}

/// Where a phase's tiles are: `nk` tiles per buffer, `tw` per tile row, output phase
/// `(a, b)`.
struct Tiles {
    nk: usize,
    tw: usize,
    a: usize,
    b: usize,
}

/// A pass's outputs: tile rows `ty0 .. ty0 + rows` of output-row parity `a`, into an
/// output of `h2` x `w2` pixels.
struct Pass {
    nk: usize,
    tw: usize,
    a: usize,
    ty0: usize,
    rows: usize,
    h2: usize,
    w2: usize,
}

/// `Bᵀ d B` of every 3x3 input tile of tile row `ty` of phase `(t.a, t.b)`, into `v`
/// (`[cin, 9, nk]`) from tile `at` on. Tile `tx` reads bordered rows `2ty + a ..= 2ty + a + 2`
/// and columns `2tx + b ..= 2tx + b + 2`.
fn transform_input(x: &Padded, t: &Tiles, ty: usize, v: &mut [f32], at: usize, simd: bool) {
    #[cfg(target_arch = "x86_64")]
    if simd {
        // SAFETY: `simd` is only set when the CPU has AVX2 and FMA ([`Upsample3x3::forward`]).
        #[allow(unsafe_code)]
        unsafe {
            avx2::transform_input_avx2(x, t, ty, v, at)
        };
        return;
    }
    let _ = simd;
    for ci in 0..x.channels() {
        let rows: [&[f32]; 3] = std::array::from_fn(|r| x.bordered_row(ci, 2 * ty + t.a + r));
        for tx in 0..t.tw {
            let c0 = 2 * tx + t.b;
            // Along x, then along y: [d0 − d1, d1, d2 − d1].
            let tr: [[f32; 3]; 3] = std::array::from_fn(|r| {
                let d = &rows[r][c0..c0 + 3];
                [d[0] - d[1], d[1], d[2] - d[1]]
            });
            for j in 0..3 {
                let col = [tr[0][j] - tr[1][j], tr[1][j], tr[2][j] - tr[1][j]];
                for (i, &val) in col.iter().enumerate() {
                    v[(ci * 9 + i * 3 + j) * t.nk + at + tx] = val;
                }
            }
        }
    }
}

/// `Aᵀ m A` of every tile of the pass for both column phases, plus the bias, into
/// `out`: tile `(ty, tx)`'s output `(dy, dx)` of phase `(a, b)` is pixel
/// `(4ty + 2dy + a, 4tx + 2dx + b)`.
fn transform_output(k: &Upsample3x3, m: &[Vec<f32>; 2], p: &Pass, out: &mut [f32], simd: bool) {
    #[cfg(target_arch = "x86_64")]
    if simd {
        // SAFETY: `simd` is only set when the CPU has AVX2 and FMA ([`Upsample3x3::forward`]).
        #[allow(unsafe_code)]
        unsafe {
            avx2::transform_output_avx2(k, m, p, out)
        };
        return;
    }
    let _ = simd;
    for co in 0..k.cout {
        for r in 0..p.rows {
            let ty = p.ty0 + r;
            for tx in 0..p.tw {
                for (b, mb) in m.iter().enumerate() {
                    let mv = |i: usize, j: usize| mb[(co * 9 + i * 3 + j) * p.nk + r * p.tw + tx];
                    for dy in 0..2 {
                        let s: [f32; 3] = std::array::from_fn(|j| mv(dy, j) + mv(dy + 1, j));
                        for dx in 0..2 {
                            let (oy, ox) = (4 * ty + 2 * dy + p.a, 4 * tx + 2 * dx + b);
                            out[(co * p.h2 + oy) * p.w2 + ox] = s[dx] + s[dx + 1] + k.bias[co];
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
    use crate::direct_conv::Conv3x3;
    use crate::elementwise::test_values as values;

    /// Upsampling then the direct 3x3 kernel, for comparison.
    fn reference(cin: usize, cout: usize, wt: &[f32], b: &[f32], x: &[f32], h: usize, w: usize) -> Vec<f32> {
        let mut up = Padded::zeros(cin, 2 * h, 2 * w);
        up.fill(x, true);
        let mut want = vec![f32::NAN; cout * 4 * h * w];
        Conv3x3::new(cin, cout, wt, Some(b)).forward_direct(&up, None, &mut want);
        want
    }

    #[test]
    fn equals_upsampling_then_convolving() {
        // One tile per phase (2x2), partial blocks of output channels (3, 5), several tile
        // rows per pass (12x12), one tile row per pass with a partial run of 8 tiles
        // (48 wide: 24 tiles), non-square with a partial run (10 wide: 5 tiles).
        for (cin, cout, h, w) in
            [(2, 3, 2, 2), (5, 8, 4, 16), (3, 5, 12, 12), (16, 16, 6, 48), (8, 4, 24, 10)]
        {
            let wt = values(cout * cin * 9, 7);
            let b = values(cout, 11);
            let x = values(cin * h * w, 3);
            let want = reference(cin, cout, &wt, &b, &x, h, w);
            let mut p = Padded::zeros(cin, h, w);
            p.fill(&x, false);
            let k = Upsample3x3::new(cin, cout, &wt, Some(&b));
            for simd in [false, cfg!(target_arch = "x86_64") && crate::elementwise::has_avx2_fma()] {
                let mut got = vec![f32::NAN; cout * 4 * h * w];
                k.run(&p, &mut got, simd);
                for (i, (a, e)) in got.iter().zip(&want).enumerate() {
                    assert!((a - e).abs() < 1e-4, "{cin}->{cout} {h}x{w} simd {simd} at {i}: {a} vs {e}");
                }
            }
        }
    }

    #[test]
    fn phase_filters_sum_the_taps_each_phase_sees() {
        // Taps 1..=9 row-major. Phase (0, 0): rows {0} | {1, 2}, columns {0} | {1, 2}:
        // [1, 2 + 3, 4 + 7, 5 + 6 + 8 + 9] = [1, 5, 11, 28]. Phase (1, 1): rows {0, 1} | {2},
        // columns {0, 1} | {2}: [1 + 2 + 4 + 5, 3 + 6, 7 + 8, 9] = [12, 9, 15, 9].
        let w: Vec<f32> = (1..=9).map(|v| v as f32).collect();
        assert_eq!(phase_filter(&w, 0, 0), [1.0, 5.0, 11.0, 28.0]);
        assert_eq!(phase_filter(&w, 1, 1), [12.0, 9.0, 15.0, 9.0]);
        // The four phases' filters together hold every tap four times (each tap reaches
        // every phase once): 4 · 45 = 180.
        let total: f64 = (0..4).flat_map(|p| phase_filter(&w, p / 2, p % 2)).sum();
        assert_eq!(total, 180.0);
    }
}
