//! The 8 symmetries of Push-T's square world (the dihedral group of the square):
//! how a world point, a T's pose and a rendered frame map under each.
//!
//! Push-T's scene maps onto a valid scene under every one of them (walls, disk and
//! T; the T is mirror-symmetric about its stem), and coverage is invariant, since
//! block and goal move together. So they are exact augmentations: the encoder's
//! pose pre-training and the coverage judge train on 8× the orientations the
//! recorded episodes hold. A perspective camera (robomimic's agentview) has no
//! such symmetry.

/// Side of the Push-T world in world units.
const WORLD: f32 = 512.0;

/// Maps a world point through symmetry `k` of the square world: bit 0 transposes
/// (x ↔ y), then bit 1 mirrors x (x → 512 − x), then bit 2 mirrors y.
pub fn augment_point(p: [f32; 2], k: u8) -> [f32; 2] {
    let mut q = if k & 1 != 0 { [p[1], p[0]] } else { p };
    if k & 2 != 0 {
        q[0] = WORLD - q[0];
    }
    if k & 4 != 0 {
        q[1] = WORLD - q[1];
    }
    q
}

/// Maps a T's pose (x, y, θ) through symmetry `k`. The T is mirror-symmetric about
/// its stem (body x → −x), so a mirrored T is a T: with L the map's linear part,
/// L·R(θ) = R(θ')·diag(−1, 1) gives θ' = −π/2 − θ (transpose), −θ (mirror x) and
/// π − θ (mirror y).
pub fn augment_pose(p: [f32; 3], k: u8) -> [f32; 3] {
    let [x, y] = augment_point([p[0], p[1]], k);
    let mut t = p[2];
    if k & 1 != 0 {
        t = -std::f32::consts::FRAC_PI_2 - t;
    }
    if k & 2 != 0 {
        t = -t;
    }
    if k & 4 != 0 {
        t = std::f32::consts::PI - t;
    }
    [x, y, t]
}

/// An `s x s` HWC frame through symmetry `k` (out[T(p)] = in[p]); walls, disk and T
/// map onto a valid scene, so this is an exact augmentation.
pub fn augment_frame(frame: &[u8], s: usize, k: u8) -> Vec<u8> {
    let mut out = vec![0u8; frame.len()];
    for y in 0..s {
        for x in 0..s {
            // Undo the mirrors, then the transpose: the source pixel of (x, y).
            let (mut sx, mut sy) = (x, y);
            if k & 4 != 0 {
                sy = s - 1 - sy;
            }
            if k & 2 != 0 {
                sx = s - 1 - sx;
            }
            if k & 1 != 0 {
                std::mem::swap(&mut sx, &mut sy);
            }
            let (o, i) = ((y * s + x) * 3, (sy * s + sx) * 3);
            out[o..o + 3].copy_from_slice(&frame[i..i + 3]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symmetries_map_points_and_angles() {
        // Transpose: (100, 30) → (30, 100); θ = 0.3 → −π/2 − 0.3.
        let p = augment_pose([100.0, 30.0, 0.3], 1);
        assert!((p[0] - 30.0).abs() < 1e-6 && (p[1] - 100.0).abs() < 1e-6);
        assert!((p[2] + std::f32::consts::FRAC_PI_2 + 0.3).abs() < 1e-6);
        // Mirror x then y: (100, 30) → (412, 482); θ → π − (−θ) = π + θ.
        let p = augment_pose([100.0, 30.0, 0.3], 6);
        assert!((p[0] - 412.0).abs() < 1e-6 && (p[1] - 482.0).abs() < 1e-6);
        assert!((p[2] - std::f32::consts::PI - 0.3).abs() < 1e-6);
        // A 2 × 2 frame [a b; c d] transposed is [a c; b d]; mirrored in x it is [b a; d c].
        let f: Vec<u8> = (0..4).flat_map(|v| [v, v, v]).collect();
        let px = |g: &[u8]| g.chunks(3).map(|c| c[0]).collect::<Vec<_>>();
        assert_eq!(px(&augment_frame(&f, 2, 1)), vec![0, 2, 1, 3]);
        assert_eq!(px(&augment_frame(&f, 2, 2)), vec![1, 0, 3, 2]);
        assert_eq!(px(&augment_frame(&f, 2, 0)), vec![0, 1, 2, 3]);
    }
}
