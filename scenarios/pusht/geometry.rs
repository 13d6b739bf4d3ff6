//! Planar geometry of Push-T: poses, the T polygon, exact coverage.
//!
//! The T is the union of two disjoint rectangles (bar and stem), so the area of
//! the intersection of two Ts is the sum of the four rectangle-rectangle
//! intersections, each an exact convex clip (Sutherland-Hodgman). No sampling,
//! no rasterisation: the score of the reference branch is exact.

use serde::{Deserialize, Serialize};

/// A planar pose in world units (x, y) and radians (theta).
///
/// A body-frame point (vx, vy) lands at
/// `(x + vx cos θ - vy sin θ, y + vx sin θ + vy cos θ)` in the world.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose2 {
    /// x position of the body origin (world units).
    pub x: f64,
    /// y position of the body origin (world units, y points down in images).
    pub y: f64,
    /// Orientation (radians).
    pub theta: f64,
}

impl Pose2 {
    /// A pose from its three components.
    pub const fn new(x: f64, y: f64, theta: f64) -> Self {
        Self { x, y, theta }
    }

    /// Maps a body-frame point to the world frame.
    pub fn apply(&self, p: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.theta.sin_cos();
        [self.x + p[0] * c - p[1] * s, self.y + p[0] * s + p[1] * c]
    }

    /// Maps a world point into the body frame (inverse of [`Pose2::apply`]).
    pub fn inverse_apply(&self, p: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.theta.sin_cos();
        let (dx, dy) = (p[0] - self.x, p[1] - self.y);
        [dx * c + dy * s, -dx * s + dy * c]
    }

    /// The pose as `[x, y, theta]`.
    pub fn to_array(&self) -> [f64; 3] {
        [self.x, self.y, self.theta]
    }
}

/// Wraps an angle into `(-π, π]`.
pub fn wrap_angle(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let mut w = a.rem_euclid(two_pi);
    if w > std::f64::consts::PI {
        w -= two_pi;
    }
    w
}

/// An axis-aligned rectangle in a body frame: `[x_min, x_max] x [y_min, y_max]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rect {
    /// `[x_min, x_max]`.
    pub x: [f64; 2],
    /// `[y_min, y_max]`.
    pub y: [f64; 2],
}

impl Rect {
    /// Area of the rectangle.
    pub fn area(&self) -> f64 {
        (self.x[1] - self.x[0]) * (self.y[1] - self.y[0])
    }

    /// Centre of the rectangle.
    pub fn centre(&self) -> [f64; 2] {
        [(self.x[0] + self.x[1]) / 2.0, (self.y[0] + self.y[1]) / 2.0]
    }

    /// Half extents `[hx, hy]`.
    pub fn half(&self) -> [f64; 2] {
        [(self.x[1] - self.x[0]) / 2.0, (self.y[1] - self.y[0]) / 2.0]
    }

    /// Whether a body-frame point lies inside (closed).
    pub fn contains(&self, p: [f64; 2]) -> bool {
        p[0] >= self.x[0] && p[0] <= self.x[1] && p[1] >= self.y[0] && p[1] <= self.y[1]
    }

    /// Distance from a body-frame point to the rectangle (0 inside).
    pub fn distance(&self, p: [f64; 2]) -> f64 {
        let dx = (self.x[0] - p[0]).max(p[0] - self.x[1]).max(0.0);
        let dy = (self.y[0] - p[1]).max(p[1] - self.y[1]).max(0.0);
        // Not `hypot` (a libm call; the renderer asks this per pixel near an edge).
        (dx * dx + dy * dy).sqrt()
    }

    /// Corners in counter-clockwise order (in a y-up sense).
    pub fn corners(&self) -> [[f64; 2]; 4] {
        [[self.x[0], self.y[0]], [self.x[1], self.y[0]], [self.x[1], self.y[1]], [self.x[0], self.y[1]]]
    }
}

/// The T shape: two disjoint rectangles in the block's body frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TShape {
    /// The horizontal bar.
    pub bar: Rect,
    /// The vertical stem.
    pub stem: Rect,
}

impl TShape {
    /// The GPC/DriftWorld T: bar x∈[-60,60], y∈[-45,-15]; stem x∈[-15,15], y∈[-15,75].
    pub const GPC: TShape = TShape {
        bar: Rect { x: [-60.0, 60.0], y: [-45.0, -15.0] },
        stem: Rect { x: [-15.0, 15.0], y: [-15.0, 75.0] },
    };

    /// The two parts.
    pub fn parts(&self) -> [Rect; 2] {
        [self.bar, self.stem]
    }

    /// Area of the T (the parts are disjoint).
    pub fn area(&self) -> f64 {
        self.bar.area() + self.stem.area()
    }

    /// Whether a body-frame point lies inside the T.
    pub fn contains(&self, p: [f64; 2]) -> bool {
        self.bar.contains(p) || self.stem.contains(p)
    }

    /// Distance from a body-frame point to the T (0 inside).
    pub fn distance(&self, p: [f64; 2]) -> f64 {
        self.bar.distance(p).min(self.stem.distance(p))
    }

    /// The world-frame polygon of each part at `pose`.
    pub fn world_parts(&self, pose: &Pose2) -> [[[f64; 2]; 4]; 2] {
        self.parts().map(|r| r.corners().map(|c| pose.apply(c)))
    }

    /// The 8 vertices of the T outline in the body frame, in order.
    pub fn outline(&self) -> [[f64; 2]; 8] {
        let (b, s) = (self.bar, self.stem);
        [
            [b.x[0], b.y[0]],
            [b.x[1], b.y[0]],
            [b.x[1], b.y[1]],
            [s.x[1], s.y[0]],
            [s.x[1], s.y[1]],
            [s.x[0], s.y[1]],
            [s.x[0], s.y[0]],
            [b.x[0], b.y[1]],
        ]
    }
}

/// Signed area of a polygon (shoelace formula; positive when counter-clockwise in y-up).
pub fn signed_area(poly: &[[f64; 2]]) -> f64 {
    let n = poly.len();
    let mut s = 0.0;
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        s += a[0] * b[1] - b[0] * a[1];
    }
    s / 2.0
}

/// Clips the convex polygon `subject` by the convex polygon `clip` (both counter-clockwise)
/// and returns the intersection polygon (Sutherland-Hodgman).
pub fn clip_convex(subject: &[[f64; 2]], clip: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut out: Vec<[f64; 2]> = subject.to_vec();
    let n = clip.len();
    for i in 0..n {
        if out.is_empty() {
            break;
        }
        let (a, b) = (clip[i], clip[(i + 1) % n]);
        // Inside = left of the directed edge a -> b.
        let side = |p: [f64; 2]| (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
        let input = std::mem::take(&mut out);
        for j in 0..input.len() {
            let (p, q) = (input[j], input[(j + 1) % input.len()]);
            let (sp, sq) = (side(p), side(q));
            if sp >= 0.0 {
                out.push(p);
            }
            if (sp >= 0.0) != (sq >= 0.0) {
                let t = sp / (sp - sq);
                out.push([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]);
            }
        }
    }
    out
}

/// Area of the intersection of the T at pose `a` and the T at pose `b` (exact).
pub fn intersection_area(shape: &TShape, a: &Pose2, b: &Pose2) -> f64 {
    let pa = shape.world_parts(a);
    let pb = shape.world_parts(b);
    let mut total = 0.0;
    for p in &pa {
        for q in &pb {
            total += signed_area(&clip_convex(p, q)).abs();
        }
    }
    total
}

/// Coverage of the goal by the block: area(block ∩ goal) / area(goal), in [0, 1].
pub fn coverage(shape: &TShape, block: &Pose2, goal: &Pose2) -> f64 {
    (intersection_area(shape, block, goal) / shape.area()).clamp(0.0, 1.0)
}

/// IoU from coverage for two shapes of equal area: c / (2 - c).
pub fn iou_from_coverage(c: f64) -> f64 {
    c / (2.0 - c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    const T: TShape = TShape::GPC;

    #[test]
    fn t_area_is_bar_plus_stem() {
        // bar 120 x 30 = 3600, stem 30 x 90 = 2700.
        assert_eq!(T.area(), 6300.0);
        assert!((signed_area(&T.outline()).abs() - 6300.0).abs() < 1e-9);
    }

    #[test]
    fn identical_poses_cover_fully() {
        let p = Pose2::new(200.0, 300.0, 0.7);
        assert!((coverage(&T, &p, &p) - 1.0).abs() < 1e-12);
        assert!((iou_from_coverage(1.0) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn disjoint_poses_cover_nothing() {
        let a = Pose2::new(100.0, 100.0, 0.0);
        let b = Pose2::new(400.0, 400.0, 1.0);
        assert_eq!(coverage(&T, &a, &b), 0.0);
    }

    #[test]
    fn shifted_by_ten_along_x() {
        // Shift x by 10: the bar overlaps 110 x 30 = 3300, the stem 20 x 90 = 1800,
        // and the shifted bar never meets the stem (disjoint y ranges): 5100 / 6300.
        let a = Pose2::new(256.0, 256.0, 0.0);
        let b = Pose2::new(266.0, 256.0, 0.0);
        let c = coverage(&T, &a, &b);
        assert!((c - 5100.0 / 6300.0).abs() < 1e-12, "{c}");
        // IoU = c / (2 - c) = (51/63) / (75/63) = 51/75 = 0.68.
        assert!((iou_from_coverage(c) - 0.68).abs() < 1e-12);
    }

    #[test]
    fn half_turn_overlap() {
        // Rotating by π about the origin maps the bar to y∈[15,45] (inside the stem's
        // y-range, x∈[-60,60]) and the stem to y∈[-75,15].
        // bar' ∩ stem = 30 x 30 = 900; stem' ∩ bar = 30 x 30 = 900;
        // stem' ∩ stem = x∈[-15,15], y∈[-15,15] = 900; bar' ∩ bar = 0. Total 2700.
        let a = Pose2::new(0.0, 0.0, 0.0);
        let b = Pose2::new(0.0, 0.0, PI);
        assert!((intersection_area(&T, &a, &b) - 2700.0).abs() < 1e-9);
    }

    #[test]
    fn coverage_is_symmetric_and_rotation_invariant() {
        let a = Pose2::new(250.0, 240.0, 0.3);
        let b = Pose2::new(262.0, 251.0, 0.3 + FRAC_PI_2 / 5.0);
        let c1 = coverage(&T, &a, &b);
        let c2 = coverage(&T, &b, &a);
        assert!((c1 - c2).abs() < 1e-12);
        // Rotating both poses about the world origin leaves the overlap unchanged.
        let rot = |p: Pose2, r: f64| {
            let (s, c) = r.sin_cos();
            Pose2::new(p.x * c - p.y * s, p.x * s + p.y * c, p.theta + r)
        };
        let c3 = coverage(&T, &rot(a, 1.1), &rot(b, 1.1));
        assert!((c1 - c3).abs() < 1e-9);
        assert!(c1 > 0.0 && c1 < 1.0);
    }

    #[test]
    fn pose_round_trip_and_wrap() {
        let p = Pose2::new(3.0, -2.0, 2.5);
        let w = p.apply([7.0, 11.0]);
        let b = p.inverse_apply(w);
        assert!((b[0] - 7.0).abs() < 1e-12 && (b[1] - 11.0).abs() < 1e-12);
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-0.5) + 0.5).abs() < 1e-12);
    }

    #[test]
    fn distance_to_t() {
        assert_eq!(T.distance([0.0, 0.0]), 0.0);
        // Beyond the stem's end (y = 75) by 5.
        assert!((T.distance([0.0, 80.0]) - 5.0).abs() < 1e-12);
        // Diagonal from the bar corner (60, -45): (3, -4) away -> 5.
        assert!((T.distance([63.0, -49.0]) - 5.0).abs() < 1e-12);
    }
}
