//! Winograd F(2x2, 3x3) for channel-major batches of images, `[c, imgs, h, w]`:
//! the 3x3 spatial convolutions of the CPU U-Net (`world_model::unet::cpu`).
//!
//! Why: after the decoder, those convolutions (im2col + one GEMM) were the
//! largest part of `rank`'s world-model time. Here every 4x4 input tile of a
//! chunk of images is transformed (`Bᵀ d B`), the 16 element-wise products with
//! the pre-transformed filters (`G g Gᵀ`) become 16 GEMMs `[cout, cin] · [cin,
//! tiles]` on the `gemm` crate's kernels — 16 multiply-adds per 2x2 output
//! instead of 36 — and the tiles are transformed back (`Aᵀ m A`) and added to the
//! output. The same algebra as [`crate::winograd`] (which works on one bordered
//! image for the decoder); this one needs no border copy of the whole batch and
//! keeps the GEMMs wide. Equal to the im2col convolution to float rounding
//! (tested below).

#[cfg(target_arch = "x86_64")]
mod avx2;

use crate::avx512_gemm::fast_matmul;
use crate::winograd::{Winograd3x3, input_2d, output_2d, transform_filter};

/// Floats per transformed buffer (`[16, c, tiles]`) per chunk of images: 8 MB.
const CHUNK: usize = 1 << 21;

/// A 3x3, stride-1, padding-1 convolution's weights in the Winograd domain:
/// `[16, cout, cin]`. The bias is the caller's.
#[derive(Clone, Debug)]
pub struct BatchWinograd {
    cin: usize,
    cout: usize,
    u: Vec<f32>,
}

impl BatchWinograd {
    /// From burn's layout, `weight` `[cout, cin, 3, 3]`.
    pub fn new(cin: usize, cout: usize, weight: &[f32]) -> Self {
        assert_eq!(weight.len(), cout * cin * 9);
        let mut u = vec![0.0; 16 * cout * cin];
        for co in 0..cout {
            for ci in 0..cin {
                let ut = transform_filter(&weight[(co * cin + ci) * 9..][..9]);
                for (p, &val) in ut.iter().enumerate() {
                    u[(p * cout + co) * cin + ci] = val;
                }
            }
        }
        Self { cin, cout, u }
    }

    /// Whether `h` x `w` images can be convolved this way (whole 2x2 tiles).
    pub fn supports(h: usize, w: usize) -> bool {
        Winograd3x3::supports(h, w)
    }

    /// Adds the convolution (no bias) of `x` to `out`.
    ///
    /// # Shapes
    /// `x`: `[cin, imgs, h, w]` -> `out`: `[cout, imgs, h, w]` (accumulated)
    pub fn forward_add(&self, x: &[f32], imgs: usize, h: usize, w: usize, out: &mut [f32]) {
        #[cfg(target_arch = "x86_64")]
        if crate::elementwise::has_avx2_fma() {
            return self.run(x, imgs, h, w, out, true);
        }
        self.run(x, imgs, h, w, out, false);
    }

    /// Chunks of images: transforms in, 16 GEMMs, transforms out. `simd`: the AVX2
    /// transforms (only when the CPU has them).
    fn run(&self, x: &[f32], imgs: usize, h: usize, w: usize, out: &mut [f32], simd: bool) {
        assert!(Self::supports(h, w));
        assert_eq!(x.len(), self.cin * imgs * h * w);
        assert_eq!(out.len(), self.cout * imgs * h * w);
        let (cin, cout) = (self.cin, self.cout);
        let per_img = (h / 2) * (w / 2);
        // Images per chunk: a whole number of 8-lane runs where the budget allows.
        let fit = (CHUNK / (16 * cin.max(cout) * per_img)).max(1);
        // Never fewer images than fill the lanes there are (up to 8): a chunk is padded to
        // whole 8-lane runs anyway, so a chunk of one image transformed and multiplied 8
        // lanes of which 7 were zeros (96 channels at 96²: 3.5 M floats a buffer per image).
        let per = if fit >= LANES { fit / LANES * LANES } else { imgs.min(LANES) }
            .min(imgs.div_ceil(LANES) * LANES);
        let lanes = per.div_ceil(LANES) * LANES;
        // Every value a chunk reads from these is written first in that chunk (`buf`'s
        // border and padding lanes are zeroed by the input transform), so stale values
        // from an earlier call never matter.
        let [mut v, mut m, mut buf] = BUFFERS.take();
        v.resize(16 * cin * per_img * lanes, 0.0);
        m.resize(16 * cout * per_img * lanes, 0.0);
        buf.resize((h + 2) * (w + 2) * lanes, 0.0);
        for i0 in (0..imgs).step_by(per) {
            let n = per.min(imgs - i0);
            let geo = Geometry { imgs, h, w, i0, n, lanes: n.div_ceil(LANES) * LANES };
            let tiles = per_img * geo.lanes;
            transform_input(x, cin, &geo, &mut buf, &mut v[..16 * cin * tiles], simd);
            for p in 0..16 {
                let a = &self.u[p * cout * cin..][..cout * cin];
                let b = &v[p * cin * tiles..][..cin * tiles];
                fast_matmul(cout, cin, tiles, a, b, &mut m[p * cout * tiles..][..cout * tiles], false);
            }
            transform_output(&m[..16 * cout * tiles], cout, &geo, &mut buf, out, simd);
        }
        BUFFERS.set([v, m, buf]);
    }
}

thread_local! {
    /// This thread's transform buffers (`v`, `m`, `buf` of [`BatchWinograd::run`]), kept
    /// from call to call: allocating them zeroed was a memset of a few MB per convolution.
    static BUFFERS: std::cell::Cell<[Vec<f32>; 3]> = const { std::cell::Cell::new([Vec::new(), Vec::new(), Vec::new()]) };
}

/// Images per vector.
const LANES: usize = 8;

/// Images `i0 .. i0 + n` of a batch of `imgs` images of `h` x `w`, laid out with the
/// image index innermost, padded to `lanes` (a multiple of 8) images.
struct Geometry {
    imgs: usize,
    h: usize,
    w: usize,
    i0: usize,
    n: usize,
    lanes: usize,
}

/// `Bᵀ d B` of every 4x4 tile (input rows and columns `2t − 1 .. 2t + 2`, zero outside)
/// of the chunk's images, into `v` `[16, c, tiles]` with tiles ordered (ty, tx, image):
/// each channel is first copied image-innermost into `buf` (`[h + 2, w + 2, lanes]`,
/// zero border), so a tile position's values for 8 images are one vector.
fn transform_input(x: &[f32], c: usize, g: &Geometry, buf: &mut [f32], v: &mut [f32], simd: bool) {
    #[cfg(target_arch = "x86_64")]
    if simd {
        // SAFETY: `simd` is only set when the CPU has AVX2 and FMA ([`BatchWinograd::forward_add`]).
        #[allow(unsafe_code)]
        unsafe {
            avx2::transform_input_avx2(x, c, g, buf, v)
        };
        return;
    }
    let _ = simd;
    let (h, w, l) = (g.h, g.w, g.lanes);
    let (th, tw, pw) = (h / 2, w / 2, w + 2);
    let tiles = th * tw * l;
    let buf = &mut buf[..(h + 2) * pw * l];
    buf.fill(0.0);
    for ci in 0..c {
        for j in 0..g.n {
            let plane = &x[(ci * g.imgs + g.i0 + j) * h * w..][..h * w];
            for (y, src) in plane.chunks_exact(w).enumerate() {
                for (xx, &val) in src.iter().enumerate() {
                    buf[((y + 1) * pw + xx + 1) * l + j] = val;
                }
            }
        }
        for ty in 0..th {
            for tx in 0..tw {
                for j0 in (0..l).step_by(LANES) {
                    // d[r][q]: input (2ty + r − 1, 2tx + q − 1) of images j0 .. j0 + 8.
                    let d: [[[f32; LANES]; 4]; 4] = std::array::from_fn(|r| {
                        std::array::from_fn(|q| {
                            let at = ((2 * ty + r) * pw + 2 * tx + q) * l + j0;
                            buf[at..at + LANES].try_into().unwrap_or([0.0; LANES])
                        })
                    });
                    let at = (ty * tw + tx) * l + j0;
                    for (i, row) in input_2d(&d).iter().enumerate() {
                        for (j, val) in row.iter().enumerate() {
                            let dst = ((i * 4 + j) * c + ci) * tiles + at;
                            v[dst..dst + LANES].copy_from_slice(val);
                        }
                    }
                }
            }
        }
    }
}

/// `Aᵀ m A` of every tile of `m` (`[16, c, tiles]`, as [`transform_input`] orders
/// them), added to the chunk's images in `out` (`[c, imgs, h, w]`) through `buf`.
fn transform_output(m: &[f32], c: usize, g: &Geometry, buf: &mut [f32], out: &mut [f32], simd: bool) {
    #[cfg(target_arch = "x86_64")]
    if simd {
        // SAFETY: `simd` is only set when the CPU has AVX2 and FMA ([`BatchWinograd::forward_add`]).
        #[allow(unsafe_code)]
        unsafe {
            avx2::transform_output_avx2(m, c, g, buf, out)
        };
        return;
    }
    let _ = simd;
    let (h, w, l) = (g.h, g.w, g.lanes);
    let (th, tw) = (h / 2, w / 2);
    let tiles = th * tw * l;
    let buf = &mut buf[..h * w * l];
    for co in 0..c {
        for ty in 0..th {
            for tx in 0..tw {
                for j0 in (0..l).step_by(LANES) {
                    let at = (ty * tw + tx) * l + j0;
                    let v: [[f32; LANES]; 16] = std::array::from_fn(|p| {
                        let src = (p * c + co) * tiles + at;
                        m[src..src + LANES].try_into().unwrap_or([0.0; LANES])
                    });
                    for (dy, [even, odd]) in output_2d(&v).iter().enumerate() {
                        let e = ((2 * ty + dy) * w + 2 * tx) * l + j0;
                        buf[e..e + LANES].copy_from_slice(even);
                        buf[e + l..e + l + LANES].copy_from_slice(odd);
                    }
                }
            }
        }
        for j in 0..g.n {
            let img = &mut out[(co * g.imgs + g.i0 + j) * h * w..][..h * w];
            for (i, o) in img.iter_mut().enumerate() {
                *o += buf[i * l + j];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::matrix::{Conv2dShape, matmul};

    use crate::elementwise::test_values as values;

    #[test]
    fn matches_im2col_and_gemm() {
        // One tile, several images per chunk, non-square, channel counts that are not
        // multiples of anything.
        // 19 images of 12x12: two full runs of 8 images (8x8 transposes over 144 = 18 · 8
        // pixels) and a partial one; 6x6: 36 pixels, a partial block of 4.
        for (cin, cout, imgs, h, w) in [
            (1, 1, 1, 2, 2),
            (3, 5, 7, 6, 6),
            (8, 4, 3, 12, 12),
            (5, 6, 2, 4, 10),
            (4, 3, 19, 12, 12),
            (2, 3, 17, 6, 6),
            // Wide and large: 16 · 96 · 24² floats per image, so the budget fits 2 images
            // (2,097,152 / 884,736); a chunk takes all 3 regardless, as many as it has lanes
            // for (at 96² the budget fitted none, and each chunk ran one image in 8 lanes).
            (96, 96, 3, 48, 48),
        ] {
            let wt = values(cout * cin * 9, 7);
            let x = values(cin * imgs * h * w, 3);
            // The reference: im2col + GEMM, as the U-Net's other path computes it.
            let shape = Conv2dShape { k: 3, stride: 1, pad: 1 };
            let mut col = vec![0.0; cin * 9 * imgs * h * w];
            shape.im2col(&x, cin, imgs, h, w, 0, imgs, &mut col);
            let start = values(cout * imgs * h * w, 5);
            let mut want = start.clone();
            matmul(cout, cin * 9, imgs * h * w, &wt, &col, &mut want, true);
            let k = BatchWinograd::new(cin, cout, &wt);
            for simd in [false, cfg!(target_arch = "x86_64") && crate::elementwise::has_avx2_fma()] {
                let mut got = start.clone();
                k.run(&x, imgs, h, w, &mut got, simd);
                for (i, (a, e)) in got.iter().zip(&want).enumerate() {
                    assert!(
                        (a - e).abs() < 1e-4,
                        "{cin}->{cout} {imgs}x{h}x{w} simd {simd} at {i}: {a} vs {e}"
                    );
                }
            }
        }
    }

    #[test]
    fn the_centre_tap_is_the_identity() {
        // A single channel with only the centre tap 1 adds the input to the output.
        let x: Vec<f32> = (0..2 * 16).map(|i| i as f32).collect();
        let mut k = [0.0f32; 9];
        k[4] = 1.0;
        let mut out = vec![1.0; 32];
        BatchWinograd::new(1, 1, &k).forward_add(&x, 2, 4, 4, &mut out);
        assert!(out.iter().zip(&x).all(|(o, v)| (o - (v + 1.0)).abs() < 1e-5), "{out:?}");
    }
}
