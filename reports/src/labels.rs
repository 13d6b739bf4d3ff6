//! Label placement for scatter plots: policies of similar quality sit close
//! together, and labels drawn at a fixed offset then overprint each other.
//!
//! [`place`] works in pixels. For each point, in order, it tries candidate
//! positions around the point, nearest first (right, left, above, below, then
//! further out on rings of growing radius), and keeps the first whose box
//! overlaps neither an earlier label nor any point marker and stays inside the
//! plot area. A label placed away from its point gets a leader line. When no
//! candidate is free (a very crowded plot) the one with the least overlap wins,
//! so a label is never dropped.

/// An axis-aligned box in pixels: left, top, width, height.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rect {
    /// Left edge.
    pub x: i32,
    /// Top edge.
    pub y: i32,
    /// Width.
    pub w: i32,
    /// Height.
    pub h: i32,
}

impl Rect {
    /// Overlapping area with `o` (0 when they only touch).
    pub fn overlap(&self, o: &Rect) -> i64 {
        let dx = (self.x + self.w).min(o.x + o.w) - self.x.max(o.x);
        let dy = (self.y + self.h).min(o.y + o.h) - self.y.max(o.y);
        if dx <= 0 || dy <= 0 { 0 } else { i64::from(dx) * i64::from(dy) }
    }

    fn inside(&self, area: &Rect) -> bool {
        self.x >= area.x
            && self.y >= area.y
            && self.x + self.w <= area.x + area.w
            && self.y + self.h <= area.y + area.h
    }
}

/// Where one label goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Placed {
    /// The label's box (its text is drawn from the top-left corner).
    pub rect: Rect,
    /// Whether it sits far enough from its point to need a leader line.
    pub leader: bool,
}

/// Gap between a marker and its label at the nearest positions (pixels).
const GAP: i32 = 6;
/// Half the size of the box kept free around each point marker (pixels).
const MARKER: i32 = 5;
/// Rings of candidate positions tried beyond the nearest ones.
const RINGS: i32 = 6;

/// Candidate top-left corners for a `w x h` label of the point `(px, py)`, nearest first.
fn candidates(px: i32, py: i32, w: i32, h: i32) -> Vec<(i32, i32, bool)> {
    let mut c = vec![
        (px + GAP, py - h - 2, false),     // upper right
        (px + GAP, py + 2, false),         // lower right
        (px - GAP - w, py - h - 2, false), // upper left
        (px - GAP - w, py + 2, false),     // lower left
        (px - w / 2, py - h - GAP, false), // above
        (px - w / 2, py + GAP, false),     // below
    ];
    for ring in 1..=RINGS {
        let d = ring * (h + 2);
        for (dx, dy) in [(0, -1), (0, 1), (1, -1), (1, 1), (-1, -1), (-1, 1)] {
            let x = match dx {
                1 => px + GAP + d,
                -1 => px - GAP - d - w,
                _ => px + GAP,
            };
            c.push((x, py - h / 2 + dy * (d + h / 2), true));
        }
    }
    c
}

/// Places labels of sizes `sizes` (pixels) for the points `points` inside `area`.
pub fn place(points: &[(i32, i32)], sizes: &[(i32, i32)], area: Rect) -> Vec<Placed> {
    let markers: Vec<Rect> = points
        .iter()
        .map(|&(x, y)| Rect { x: x - MARKER, y: y - MARKER, w: 2 * MARKER, h: 2 * MARKER })
        .collect();
    let mut placed: Vec<Placed> = Vec::with_capacity(points.len());
    for (&(px, py), &(w, h)) in points.iter().zip(sizes) {
        let cost = |r: &Rect| -> i64 {
            let labels: i64 = placed.iter().map(|p| p.rect.overlap(r)).sum();
            let marks: i64 = markers.iter().map(|m| m.overlap(r)).sum();
            labels + marks + if r.inside(&area) { 0 } else { i64::from(w) * i64::from(h) }
        };
        let mut best: Option<(i64, Placed)> = None;
        for (x, y, leader) in candidates(px, py, w, h) {
            let rect = Rect { x, y, w, h };
            let c = cost(&rect);
            if best.is_none_or(|(b, _)| c < b) {
                best = Some((c, Placed { rect, leader }));
            }
            if c == 0 {
                break;
            }
        }
        if let Some((_, p)) = best {
            placed.push(p);
        }
    }
    placed
}

#[cfg(test)]
mod tests {
    use super::*;

    const AREA: Rect = Rect { x: 0, y: 0, w: 500, h: 400 };

    #[test]
    fn an_isolated_point_gets_the_upper_right_position() {
        let p = place(&[(100, 200)], &[(60, 12)], AREA);
        // x = 100 + GAP = 106; y = 200 − 12 − 2 = 186.
        assert_eq!(p, vec![Placed { rect: Rect { x: 106, y: 186, w: 60, h: 12 }, leader: false }]);
    }

    #[test]
    fn clustered_points_get_labels_that_do_not_overlap() {
        // Seven policies within 30 px of each other, as in a flat world-model score.
        let pts: Vec<(i32, i32)> = (0..7).map(|i| (200 + 5 * i, 200 - 2 * (i % 3))).collect();
        let p = place(&pts, &[(70, 13); 7], AREA);
        assert_eq!(p.len(), 7);
        for i in 0..7 {
            assert!(p[i].rect.inside(&AREA));
            for j in 0..i {
                assert_eq!(p[i].rect.overlap(&p[j].rect), 0, "labels {i} and {j} overlap: {p:?}");
            }
            for &(x, y) in &pts {
                let m = Rect { x: x - MARKER, y: y - MARKER, w: 2 * MARKER, h: 2 * MARKER };
                assert_eq!(p[i].rect.overlap(&m), 0, "label {i} covers a marker");
            }
        }
        assert!(p.iter().any(|l| l.leader), "a cluster this tight needs leader lines");
    }

    #[test]
    fn a_point_at_the_right_edge_is_labelled_on_its_left() {
        let p = place(&[(490, 200)], &[(60, 12)], AREA);
        // Upper right would end at 556 > 500; upper left starts at 490 − 6 − 60 = 424.
        assert_eq!(p[0].rect, Rect { x: 424, y: 186, w: 60, h: 12 });
    }

    #[test]
    fn overlap_is_the_shared_area() {
        let a = Rect { x: 0, y: 0, w: 10, h: 10 };
        // Shares x 5..10 and y 8..10: 5 × 2 = 10 px².
        assert_eq!(a.overlap(&Rect { x: 5, y: 8, w: 10, h: 10 }), 10);
        assert_eq!(a.overlap(&Rect { x: 10, y: 0, w: 5, h: 5 }), 0);
    }
}
