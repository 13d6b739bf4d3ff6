//! Winograd F(2x2, 3x3) convolution on the CPU: the same 3x3, stride-1,
//! padding-1 convolution as [`crate::direct_conv`], with 2.25x fewer
//! multiply-adds.
//!
//! Why: `rank` spends most of its world-model time in the frame decoder's 3x3
//! convolutions, and the direct kernel already runs near what one core's FMA
//! units give. Winograd's minimal filtering (Lavin & Gray 2016) computes each
//! 2x2 output tile from a 4x4 input tile with 16 multiplies per input/output
//! channel pair instead of 36: every tile's input is transformed (`Bᵀ d B`),
//! multiplied element-wise by the pre-transformed filter (`G g Gᵀ`) and summed
//! over input channels — 16 independent matrix products over all tiles — and
//! transformed back (`Aᵀ m A`). The transforms use only 0, ±1 and ½, so the
//! result equals the direct convolution to float rounding (tested below).
//!
//! The tiles of a few tile rows are processed together (about 48 per pass), so the
//! matrix products run on whole 8-lane vectors of tiles; they keep 4 output
//! channels x 24 tiles in twelve AVX2 registers across the reduction. Needs even
//! heights and widths ([`Winograd3x3::supports`]); [`crate::direct_conv::Conv3x3`]
//! falls back to its direct kernel otherwise.

mod algebra;
#[cfg(target_arch = "x86_64")]
mod avx2;
pub mod upsample;

pub(crate) use algebra::{input_2d, output_2d, transform_filter};

use crate::padded::Padded;

/// Output channels per register tile.
const OUT: usize = 4;
/// Tiles per vector.
const LANES: usize = 8;
/// Vectors of tiles per register tile.
const VECS: usize = 3;
/// Aim for about this many tiles per pass (a few tile rows of a small map, one of a large).
const TILES_PER_PASS: usize = 48;

/// A 3x3 convolution's weights in the Winograd domain: `[16, cout / 4, cin, 4]`
/// (zero-padded to whole blocks of output channels), and its bias.
#[derive(Clone, Debug)]
pub struct Winograd3x3 {
    cin: usize,
    cout: usize,
    u: Vec<f32>,
    bias: Vec<f32>,
}

impl Winograd3x3 {
    /// From burn's layout: `weight` `[cout, cin, 3, 3]`, `bias` `[cout]` (zeros when absent).
    pub fn new(cin: usize, cout: usize, weight: &[f32], bias: Option<&[f32]>) -> Self {
        assert_eq!(weight.len(), cout * cin * 9);
        let u = pack_filters(cin, cout, |co, ci| transform_filter(&weight[(co * cin + ci) * 9..][..9]));
        Self { cin, cout, u, bias: bias_or_zeros(cout, bias) }
    }

    /// Whether a `h` x `w` map can be convolved this way (whole 2x2 tiles).
    pub fn supports(h: usize, w: usize) -> bool {
        h.is_multiple_of(2) && w.is_multiple_of(2) && h > 0 && w > 0
    }

    /// Convolves `x` into `out` (`[cout, h, w]`), adding `residual` (same shape) when given.
    ///
    /// # Shapes
    /// `x`: `[cin, h, w]` (bordered) -> `out`: `[cout, h, w]`
    pub fn forward(&self, x: &Padded, residual: Option<&[f32]>, out: &mut [f32]) {
        let (h, w) = (x.height(), x.width());
        assert!(Self::supports(h, w));
        assert_eq!(x.channels(), self.cin);
        assert_eq!(out.len(), self.cout * h * w);
        let (th, tw) = (h / 2, w / 2);
        let rows = (TILES_PER_PASS / tw).clamp(1, th);
        let blocks = self.cout.div_ceil(OUT);
        let mut scratch = SCRATCH.take().resize(self.cin, blocks * OUT, rows * tw, tw);
        for ty0 in (0..th).step_by(rows) {
            let n = rows.min(th - ty0);
            for r in 0..n {
                transform_input(x, ty0 + r, &mut scratch, r * tw);
            }
            self.multiply(&mut scratch);
            let pass = Pass { ty0, rows: n, h, w };
            transform_output(self, &scratch, &pass, residual, out);
        }
        SCRATCH.set(scratch);
    }

    /// `m[p] = u[p]ᵀ v[p]` for each of the 16 positions: `[cout, tiles] = [cout, cin] · [cin, tiles]`.
    fn multiply(&self, s: &mut Scratch) {
        products(&self.u, self.cin, 16, &s.v, &mut s.m, s.tiles);
    }
}

/// Transformed filters laid out for [`products`]: `[P, cout / 4, cin, 4]`, zero-padded
/// to whole blocks of output channels; `filter(co, ci)` gives one filter's `P` points.
fn pack_filters<const P: usize>(
    cin: usize,
    cout: usize,
    filter: impl Fn(usize, usize) -> [f32; P],
) -> Vec<f32> {
    let blocks = cout.div_ceil(OUT);
    let mut u = vec![0.0; P * blocks * cin * OUT];
    for co in 0..cout {
        for ci in 0..cin {
            for (p, &val) in filter(co, ci).iter().enumerate() {
                u[((p * blocks + co / OUT) * cin + ci) * OUT + co % OUT] = val;
            }
        }
    }
    u
}

/// `bias` as a vector of `cout` values, zeros when absent.
fn bias_or_zeros(cout: usize, bias: Option<&[f32]>) -> Vec<f32> {
    bias.map_or_else(|| vec![0.0; cout], <[f32]>::to_vec)
}

/// For each of `points` positions `p`: `m[·, p, ·] = u[p]ᵀ v[·, p, ·]`, where `u` is
/// `[points, blocks, cin, 4]`, `v` `[cin, points, nk]` and `m` `[blocks · 4, points, nk]`
/// (`nk` a whole number of 8-tile vectors): the Winograd-domain products of
/// [`Winograd3x3`] (16 points) and of [`upsample::Upsample3x3`] (9 points).
fn products(u: &[f32], cin: usize, points: usize, v: &[f32], m: &mut [f32], nk: usize) {
    assert!(nk.is_multiple_of(LANES));
    #[cfg(target_arch = "x86_64")]
    if crate::elementwise::has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above), the
        // requirement of calling a function compiled with those features.
        #[allow(unsafe_code)]
        unsafe {
            avx2::products_avx2_fma(u, cin, points, v, m, nk)
        };
        return;
    }
    products_portable(u, cin, points, v, m, nk);
}

/// Per-pass buffers: transformed inputs `v` `[cin, 16, tiles]` and products `m`
/// `[cout4, 16, tiles]` (tiles rounded up to whole vectors): a channel's 16 runs are
/// neighbours, as the transforms read and write them together.
#[derive(Default)]
struct Scratch {
    cin: usize,
    /// Tiles per pass, rounded up to whole register tiles.
    tiles: usize,
    /// Tiles per tile row.
    row_tiles: usize,
    v: Vec<f32>,
    m: Vec<f32>,
}

thread_local! {
    /// The buffers of this thread's last convolution, reused by the next (they are
    /// large enough that fresh ones cost page faults and zeroing on every call).
    static SCRATCH: std::cell::Cell<Scratch> = const {
        std::cell::Cell::new(Scratch { cin: 0, tiles: 0, row_tiles: 0, v: Vec::new(), m: Vec::new() })
    };
}

impl Scratch {
    /// Buffers for a pass of `tiles` tiles (`row_tiles` per tile row), keeping the
    /// allocations. Values left from an earlier pass only ever meet padding tiles,
    /// whose products are never written out.
    fn resize(mut self, cin: usize, cout4: usize, tiles: usize, row_tiles: usize) -> Self {
        let tiles = tiles.div_ceil(LANES) * LANES;
        self.v.resize(16 * cin * tiles, 0.0);
        // One run of 8 more: a row's last, partial run of tiles is loaded whole.
        self.m.resize(16 * cout4 * tiles + LANES, 0.0);
        Self { cin, tiles, row_tiles, ..self }
    }
}

/// `Bᵀ d B` of every 4x4 input tile of tile row `ty`, into `s.v` from tile `at` on.
fn transform_input(x: &Padded, ty: usize, s: &mut Scratch, at: usize) {
    #[cfg(target_arch = "x86_64")]
    if crate::elementwise::has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above).
        #[allow(unsafe_code)]
        unsafe {
            avx2::transform_input_avx2(x, ty, s, at)
        };
        return;
    }
    transform_input_impl(x, ty, s, at);
}

/// Eight tiles at a time: the 4 input rows' 18 columns are copied into registers,
/// transformed along x (B), then along y (Bᵀ), and stored as 16 runs of 8 tiles.
#[inline(always)]
fn transform_input_impl(x: &Padded, ty: usize, s: &mut Scratch, at: usize) {
    let (tw, cin, nk) = (s.row_tiles, s.cin, s.tiles);
    for ci in 0..cin {
        // Bordered row 2ty + r is input row 2ty + r - 1: the tile's top row sits one above.
        let rows: [&[f32]; 4] = std::array::from_fn(|r| x.bordered_row(ci, 2 * ty + r));
        for x0 in (0..tw).step_by(LANES) {
            let n = LANES.min(tw - x0);
            // Tile x0 + t reads bordered columns 2(x0 + t) .. 2(x0 + t) + 3.
            let mut d = [[0.0f32; 2 * LANES + 2]; 4];
            for (dr, row) in d.iter_mut().zip(&rows) {
                let src = &row[2 * x0..];
                if src.len() >= dr.len() {
                    dr.copy_from_slice(&src[..2 * LANES + 2]);
                } else {
                    dr.iter_mut().zip(src).for_each(|(a, &b)| *a = b);
                }
            }
            // Tile k reads bordered columns 2k .. 2k + 3 of each row.
            let cols: [[[f32; LANES]; 4]; 4] =
                std::array::from_fn(|r| std::array::from_fn(|q| std::array::from_fn(|k| d[r][2 * k + q])));
            for (i, row) in input_2d(&cols).iter().enumerate() {
                for (j, vij) in row.iter().enumerate() {
                    let dst = (ci * 16 + i * 4 + j) * nk + at + x0;
                    put(&mut s.v[dst..], vij, n);
                }
            }
        }
    }
}

/// Where a pass's tiles go: tile rows `ty0 .. ty0 + rows` of an `h` x `w` output.
struct Pass {
    ty0: usize,
    rows: usize,
    h: usize,
    w: usize,
}

/// `Aᵀ m A` for every tile of the pass, plus bias and residual, into `out`.
fn transform_output(k: &Winograd3x3, s: &Scratch, pass: &Pass, residual: Option<&[f32]>, out: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if crate::elementwise::has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above).
        #[allow(unsafe_code)]
        unsafe {
            avx2::transform_output_avx2(k, s, pass, residual, out)
        };
        return;
    }
    transform_output_impl(k, s, pass, residual, out);
}

/// Eight tiles at a time: 16 runs of 8 products, Aᵀ along y then x, interleaved into
/// two output rows of 16 pixels.
#[inline(always)]
fn transform_output_impl(
    k: &Winograd3x3,
    s: &Scratch,
    pass: &Pass,
    residual: Option<&[f32]>,
    out: &mut [f32],
) {
    let (tw, nk) = (s.row_tiles, s.tiles);
    let (h, w) = (pass.h, pass.w);
    for co in 0..k.cout {
        let b = k.bias[co];
        for r in 0..pass.rows {
            let (oy, k0) = (2 * (pass.ty0 + r), r * tw);
            for x0 in (0..tw).step_by(LANES) {
                let n = LANES.min(tw - x0);
                let mut m = [[0.0f32; LANES]; 16];
                for (p, mp) in m.iter_mut().enumerate() {
                    let src = (co * 16 + p) * nk + k0 + x0;
                    put(mp, &s.m[src..], n);
                }
                // Pixel (oy + dy, 2(x0 + t) + dx), interleaved.
                for (dy, [even, odd]) in output_2d(&m).iter().enumerate() {
                    let mut px = [0.0f32; 2 * LANES];
                    for (t, pair) in px.chunks_exact_mut(2).enumerate() {
                        pair[0] = even[t] + b;
                        pair[1] = odd[t] + b;
                    }
                    let at = (co * h + oy + dy) * w + 2 * x0;
                    let dst = &mut out[at..at + 2 * n];
                    if let Some(res) = residual {
                        for ((v, &r), _) in px.iter_mut().zip(&res[at..]).zip(0..2 * n) {
                            *v += r;
                        }
                    }
                    put(dst, &px, 2 * n);
                }
            }
        }
    }
}

/// Copies the first `n` of `src` into `dst`: a fixed-size copy (a few vector moves)
/// when `n` is a whole run of 8 or 16, element by element otherwise.
#[inline(always)]
fn put(dst: &mut [f32], src: &[f32], n: usize) {
    if n == LANES {
        dst[..LANES].copy_from_slice(&src[..LANES]);
    } else if n == 2 * LANES {
        dst[..2 * LANES].copy_from_slice(&src[..2 * LANES]);
    } else {
        dst.iter_mut().zip(src).take(n).for_each(|(a, &b)| *a = b);
    }
}

/// [`products`] in plain Rust (CPUs without AVX2 + FMA).
fn products_portable(u: &[f32], cin: usize, points: usize, v: &[f32], m: &mut [f32], nk: usize) {
    let blocks = u.len() / (points * cin * OUT);
    let mut acc = vec![0.0f32; nk];
    for p in 0..points {
        for b in 0..blocks {
            let wb = &u[(p * blocks + b) * cin * OUT..][..cin * OUT];
            for j in 0..OUT {
                acc.fill(0.0);
                for ci in 0..cin {
                    let wv = wb[ci * OUT + j];
                    let v = &v[(ci * points + p) * nk..][..nk];
                    for (a, &x) in acc.iter_mut().zip(v) {
                        *a += wv * x;
                    }
                }
                let dst = ((b * OUT + j) * points + p) * nk;
                m[dst..dst + nk].copy_from_slice(&acc);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::direct_conv::Conv3x3;

    use crate::elementwise::test_values as values;

    #[test]
    fn matches_the_direct_kernel() {
        // Partial blocks of output channels (3, 5), maps of one tile, of a few tile rows
        // per pass (12x12: 6 rows of 6 tiles = 36 -> 40 with padding), and of one row per
        // pass (96 wide), non-square.
        for (cin, cout, h, w) in
            [(2, 3, 2, 2), (5, 8, 4, 16), (3, 5, 12, 12), (16, 16, 6, 96), (8, 4, 24, 10)]
        {
            let wt = values(cout * cin * 9, 7);
            let b = values(cout, 11);
            let x = values(cin * h * w, 3);
            let mut p = Padded::zeros(cin, h, w);
            p.fill(&x, false);
            let direct = Conv3x3::new(cin, cout, &wt, Some(&b));
            let mut want = vec![f32::NAN; cout * h * w];
            direct.forward_direct(&p, None, &mut want);
            let k = Winograd3x3::new(cin, cout, &wt, Some(&b));
            let mut got = vec![f32::NAN; cout * h * w];
            k.forward(&p, None, &mut got);
            for (i, (a, e)) in got.iter().zip(&want).enumerate() {
                assert!((a - e).abs() < 1e-4, "{cin}->{cout} {h}x{w} at {i}: {a} vs {e}");
            }
            // The residual is added on the way out.
            k.forward(&p, Some(&want), &mut got);
            assert!(got.iter().zip(&want).all(|(a, e)| (a - 2.0 * e).abs() < 1e-4));
            // The portable products agree with the vector ones.
            let tiles = (TILES_PER_PASS / (w / 2)).clamp(1, h / 2) * w / 2;
            let mut s = Scratch::default().resize(cin, cout.div_ceil(OUT) * OUT, tiles, w / 2);
            transform_input(&p, 0, &mut s, 0);
            products_portable(&k.u, cin, 16, &s.v, &mut s.m, s.tiles);
            let portable = s.m.clone();
            k.multiply(&mut s);
            assert!(portable.iter().zip(&s.m).all(|(a, e)| (a - e).abs() < 1e-4));
        }
    }

    #[test]
    fn a_single_tap_filter_shifts_the_image() {
        // Only the centre tap is 1: the output equals the input. Only the top-left tap is
        // 1: output (y, x) = input (y - 1, x - 1), zero on the first row and column.
        let (h, w) = (4, 4);
        let x: Vec<f32> = (0..16).map(|i| i as f32).collect();
        let mut p = Padded::zeros(1, h, w);
        p.fill(&x, false);
        let mut centre = [0.0f32; 9];
        centre[4] = 1.0;
        let mut out = vec![0.0; 16];
        Winograd3x3::new(1, 1, &centre, None).forward(&p, None, &mut out);
        assert!(out.iter().zip(&x).all(|(a, e)| (a - e).abs() < 1e-6), "{out:?}");
        let mut corner = [0.0f32; 9];
        corner[0] = 1.0;
        Winograd3x3::new(1, 1, &corner, None).forward(&p, None, &mut out);
        // Row 1 is [0, x(0,0), x(0,1), x(0,2)] = [0, 0, 1, 2]; row 0 is all zero.
        assert_eq!(&out[..4], &[0.0; 4]);
        assert!(out[4..8].iter().zip([0.0, 0.0, 1.0, 2.0]).all(|(a, e)| (a - e).abs() < 1e-6));
    }
}
