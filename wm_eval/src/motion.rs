//! `wm eval`'s breakdown of 64-frame SSIM by how far the block moves in each video:
//! where a world model loses its quality — on still scenes, on light nudges, or on
//! long pushes — beside "nothing moves", which is perfect on still scenes.
//!
//! A video's block motion is the farthest any corner of the T travels, over the
//! generated frames, from where it was at the last context frame (world units; the
//! workspace is 512 wide, the T's bar 120 long). A rigid body's largest point
//! displacement is reached at a vertex of its convex hull, so the corners measure
//! translation and rotation together.

use std::collections::HashMap;

use scenarios::pusht::{Pose2, TShape};
use serde::Serialize;
use world_model::eval::EvalRow;

/// Motion bins (world units, lower bound included): still, nudged (up to a third of
/// the bar's length), pushed, pushed far, pushed across the workspace.
pub const BINS: [(f64, f64); 5] =
    [(0.0, 5.0), (5.0, 40.0), (40.0, 100.0), (100.0, 200.0), (200.0, f64::INFINITY)];

/// What `eval.json` says the breakdown is.
pub const NOTE: &str = "64-frame videos grouped by block motion: the farthest any corner of the T travels, \
    over the generated frames, from its pose at the last context frame (world units, from the dataset's state \
    rows); each row's mean SSIM over the videos of the bin";

/// The farthest any corner of `shape` travels from its place at `reference` to its
/// place at any of `poses` (world units).
pub fn block_motion(shape: &TShape, reference: &Pose2, poses: impl Iterator<Item = Pose2>) -> f64 {
    let corners: Vec<[f64; 2]> = shape.parts().iter().flat_map(|r| r.corners()).collect();
    let at_ref: Vec<[f64; 2]> = corners.iter().map(|&c| reference.apply(c)).collect();
    poses
        .flat_map(|p| {
            corners.iter().zip(&at_ref).map(move |(&c, r)| {
                let q = p.apply(c);
                (q[0] - r[0]).hypot(q[1] - r[1])
            })
        })
        .fold(0.0, f64::max)
}

/// One bin's videos and each evaluated row's mean SSIM over them.
#[derive(Debug, PartialEq, Serialize)]
pub struct MotionBin {
    /// Lower bound (included).
    pub from: f64,
    /// Upper bound (excluded); `None` for the last bin.
    pub to: Option<f64>,
    /// Videos in the bin.
    pub videos: usize,
    /// `(row name, mean SSIM)` for each 64-frame row, in `rows`' order; empty when
    /// the bin has no videos.
    pub ssim: Vec<(String, f64)>,
}

/// Groups the 64-frame rows' videos by `motion` (block motion by video start step).
/// Videos with no motion entry are left out.
pub fn by_motion(rows: &[EvalRow], motion: &HashMap<usize, f64>) -> Vec<MotionBin> {
    let rows: Vec<&EvalRow> = rows.iter().filter(|r| r.horizon == "64").collect();
    BINS.iter()
        .map(|&(lo, hi)| {
            let inside = |start: &usize| motion.get(start).is_some_and(|m| (lo..hi).contains(m));
            let videos = motion.keys().filter(|s| inside(s)).count();
            let ssim = if videos == 0 {
                Vec::new()
            } else {
                rows.iter()
                    .map(|r| {
                        let v: Vec<f64> =
                            r.per_video.iter().filter(|v| inside(&v.start)).map(|v| v.ssim).collect();
                        (r.name.clone(), v.iter().sum::<f64>() / v.len().max(1) as f64)
                    })
                    .collect()
            };
            MotionBin { from: lo, to: hi.is_finite().then_some(hi), videos, ssim }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use world_model::eval::VideoMetrics;

    use super::*;

    #[test]
    fn translation_moves_every_corner_by_its_length() {
        // A 3-4-5 shift: every corner moves 5.
        let p0 = Pose2::new(200.0, 200.0, 0.3);
        let m = block_motion(&TShape::GPC, &p0, [Pose2::new(203.0, 204.0, 0.3)].into_iter());
        assert!((m - 5.0).abs() < 1e-9, "{m}");
        assert_eq!(block_motion(&TShape::GPC, &p0, [p0].into_iter()), 0.0);
    }

    #[test]
    fn rotation_moves_the_farthest_corner_most() {
        // Turning by θ about the body origin moves a corner at radius r by 2 r sin(θ/2).
        // The GPC T's corners farthest from its origin are the stem's (±15, 75), at
        // r = √(15² + 75²) = 76.49; the bar's outer ones (±60, −45) are at 75.
        let p0 = Pose2::new(250.0, 250.0, 0.0);
        let theta = 0.2f64;
        let m = block_motion(&TShape::GPC, &p0, [Pose2::new(250.0, 250.0, theta)].into_iter());
        let want = 2.0 * 15f64.hypot(75.0) * (theta / 2.0).sin();
        assert!((m - want).abs() < 1e-9, "{m} vs {want}");
    }

    fn row(name: &str, ssim: &[(usize, f64)]) -> EvalRow {
        EvalRow {
            name: name.into(),
            objective: "drifting".into(),
            horizon: "64".into(),
            mse: 0.0,
            psnr: 0.0,
            ssim: 0.0,
            ms_per_frame: 0.0,
            frames: 0,
            videos: ssim.len(),
            ssim_curve: Vec::new(),
            per_video: ssim
                .iter()
                .map(|&(start, ssim)| VideoMetrics { start, mse: 0.0, psnr: 0.0, ssim })
                .collect(),
            ssim_ci: None,
        }
    }

    #[test]
    fn videos_are_binned_by_motion_and_averaged_per_row() {
        // Videos from steps 10 (motion 0), 20 (4.9), 30 (100): the first two still.
        let motion: HashMap<usize, f64> = [(10, 0.0), (20, 4.9), (30, 100.0)].into();
        let rows =
            [row("m", &[(10, 0.90), (20, 0.80), (30, 0.70)]), row("p", &[(10, 1.0), (20, 1.0), (30, 0.5)])];
        let bins = by_motion(&rows, &motion);
        assert_eq!(bins.len(), 5);
        // Still: (0.90 + 0.80) / 2 = 0.85 for m, 1.0 for p.
        assert_eq!(bins[0].videos, 2);
        assert!((bins[0].ssim[0].1 - 0.85).abs() < 1e-12 && bins[0].ssim[1] == ("p".into(), 1.0));
        assert_eq!((bins[1].videos, bins[1].ssim.len()), (0, 0));
        assert_eq!((bins[3].videos, bins[3].to), (1, Some(200.0)));
        assert_eq!(bins[3].ssim, vec![("m".into(), 0.70), ("p".into(), 0.5)]);
        assert_eq!((bins[4].videos, bins[4].to), (0, None));
    }
}
