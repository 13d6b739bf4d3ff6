//! Frames between the harness's bytes and burn's tensors: `s × s` HWC RGB images (what tasks
//! render and datasets store) to `[n, 3, s, s]` values in [-1, 1] (what the networks read), and
//! back, rounded and clamped to bytes or as unrounded values in [0, 1].

use burn::tensor::{Device, Tensor, TensorData};

/// `n` fixed, frame-like inputs `[n, 3, s, s]`: a deterministic pattern in [-1, 1] with edges at
/// several scales, for telling whether two encoders encode alike.
pub fn probe_frames(n: usize, s: usize, device: &Device) -> Tensor<4> {
    let v: Vec<f32> =
        (0..n * 3 * s * s).map(|i| (((i * 7919) % 251) as f32 / 125.0 - 1.0).clamp(-1.0, 1.0)).collect();
    Tensor::from_data(TensorData::new(v, [n, 3, s, s]), device)
}

/// Byte frames (HWC) to a `[n, 3, s, s]` tensor in [-1, 1].
pub fn frames_to_tensor(frames: &[&[u8]], s: usize, device: &Device) -> Tensor<4> {
    Tensor::from_data(TensorData::new(frames_to_vec(frames, s), [frames.len(), 3, s, s]), device)
}

/// Frames of HWC values in [0, 1] ([`tensor_to_unit_floats`]) to `[n, 3, s, s]`, as they are.
pub fn unit_floats_to_tensor(frames: &[&[f32]], s: usize, device: &Device) -> Tensor<4> {
    Tensor::from_data(TensorData::new(hwc_to_chw(frames, s, |x| x), [frames.len(), 3, s, s]), device)
}

/// Byte frames (HWC) to `[n, 3, s, s]` values in [-1, 1].
pub fn frames_to_vec(frames: &[&[u8]], s: usize) -> Vec<f32> {
    hwc_to_chw(frames, s, |b| f32::from(b) / 127.5 - 1.0)
}

/// `s × s` HWC RGB frames to `[n, 3, s, s]` values, each mapped by `f`.
fn hwc_to_chw<T: Copy>(frames: &[&[T]], s: usize, f: impl Fn(T) -> f32) -> Vec<f32> {
    let plane = s * s;
    let mut v = vec![0f32; frames.len() * 3 * plane];
    for (k, fr) in frames.iter().enumerate() {
        for p in 0..plane {
            for c in 0..3 {
                v[(k * 3 + c) * plane + p] = f(fr[p * 3 + c]);
            }
        }
    }
    v
}

/// `[b, 3, h, w]` tensor in [-1, 1] to `b` HWC byte images (clamped, rounded).
pub fn tensor_to_frames(t: Tensor<4>) -> Vec<Vec<u8>> {
    tensor_to_hwc(t, |x| ((x.clamp(-1.0, 1.0) + 1.0) * 127.5).round() as u8)
}

/// Decoded frames `[b, 3, h, w]` in [-1, 1] as HWC values in [0, 1], unclamped and unrounded:
/// what [`tensor_to_frames`] rounds to bytes (`x·0.5 + 0.5`).
pub fn tensor_to_unit_floats(t: Tensor<4>) -> Vec<Vec<f32>> {
    tensor_to_hwc(t, |x| x * 0.5 + 0.5)
}

/// Each of `t`'s `[b, c, h, w]` images as HWC RGB (its first 3 channels), every value mapped by `f`.
fn tensor_to_hwc<T: Copy + Default>(t: Tensor<4>, f: impl Fn(f32) -> T) -> Vec<Vec<T>> {
    let [b, c, h, w] = t.dims();
    let v: Vec<f32> = t.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default();
    let plane = h * w;
    (0..b)
        .map(|k| {
            let mut img = vec![T::default(); plane * 3];
            for p in 0..plane {
                for ch in 0..c.min(3) {
                    img[p * 3 + ch] = f(v[k * c * plane + ch * plane + p]);
                }
            }
            img
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_round_trip_through_tensors() {
        // Byte b maps to b / 127.5 - 1 and back: (x + 1) · 127.5 rounded is b again.
        let a: Vec<u8> = (0..4 * 4 * 3).map(|i| (i * 5 % 256) as u8).collect();
        let b: Vec<u8> = a.iter().map(|v| 255 - v).collect();
        let t = frames_to_tensor(&[&a, &b], 4, &Device::flex());
        assert_eq!(t.dims(), [2, 3, 4, 4]);
        assert_eq!(tensor_to_frames(t.clone()), vec![a.clone(), b]);
        // [0, 1] floats: byte b is (b / 127.5 - 1) · 0.5 + 0.5 = b / 255 (to f32 rounding).
        let unit = tensor_to_unit_floats(t);
        assert!(unit[0].iter().zip(&a).all(|(u, &b)| (u - f32::from(b) / 255.0).abs() < 1e-6));
        // They go into a tensor as they are, channel-major: value (pixel p, channel c) at c·16 + p.
        let back = unit_floats_to_tensor(&[&unit[0]], 4, &Device::flex());
        let v = back.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default();
        assert!((0..16).all(|p| (0..3).all(|c| v[c * 16 + p] == unit[0][p * 3 + c])));
    }
}
