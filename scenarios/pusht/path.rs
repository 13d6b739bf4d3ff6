//! Collision-free agent paths around the block (grid A* plus string pulling).
//!
//! The expert must reach the far side of the T without nudging it. The free
//! space is every point whose distance to the T exceeds the agent radius plus a
//! margin; A* runs on a coarse grid over the world and the result is shortened
//! by keeping only the waypoints that cannot be skipped by a free straight line.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::geometry::{Pose2, TShape};

/// A planner for one block pose.
pub struct PathPlanner<'a> {
    /// The T.
    pub shape: &'a TShape,
    /// The block pose the path must avoid.
    pub block: Pose2,
    /// Required clearance between the agent's centre and the T.
    pub clearance: f64,
    /// World side.
    pub world: f64,
}

const CELL: f64 = 8.0;

impl PathPlanner<'_> {
    /// Whether the agent centre at `p` keeps its clearance.
    pub fn free(&self, p: [f64; 2]) -> bool {
        self.shape.distance(self.block.inverse_apply(p)) >= self.clearance
    }

    /// Whether the straight segment a -> b keeps its clearance (checked every 2 units).
    pub fn segment_free(&self, a: [f64; 2], b: [f64; 2]) -> bool {
        let len = (b[0] - a[0]).hypot(b[1] - a[1]);
        let n = (len / 2.0).ceil().max(1.0) as usize;
        (0..=n).all(|i| {
            let t = i as f64 / n as f64;
            self.free([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])])
        })
    }

    /// Waypoints from `start` to `goal` (excluding `start`, ending at `goal`), or
    /// `None` when no free path exists on the grid. A start inside the clearance
    /// zone is allowed: the path first leaves it by the nearest free cell.
    pub fn plan(&self, start: [f64; 2], goal: [f64; 2]) -> Option<Vec<[f64; 2]>> {
        if self.segment_free(start, goal) {
            return Some(vec![goal]);
        }
        let n = (self.world / CELL).ceil() as usize;
        let centre = |i: usize| (i as f64 + 0.5) * CELL;
        let cell_of = |v: f64| ((v / CELL).floor().max(0.0) as usize).min(n - 1);
        let free: Vec<bool> = (0..n * n).map(|k| self.free([centre(k % n), centre(k / n)])).collect();
        let s = cell_of(start[1]) * n + cell_of(start[0]);
        let g = cell_of(goal[1]) * n + cell_of(goal[0]);
        let h = |k: usize| {
            let (x, y) = ((k % n) as f64, (k / n) as f64);
            ((x - (g % n) as f64).hypot(y - (g / n) as f64) * 1000.0) as u64
        };
        let mut dist = vec![u64::MAX; n * n];
        let mut prev = vec![usize::MAX; n * n];
        let mut heap = BinaryHeap::new();
        dist[s] = 0;
        heap.push(Reverse((h(s), s)));
        while let Some(Reverse((_, k))) = heap.pop() {
            if k == g {
                break;
            }
            let (x, y) = ((k % n) as i64, (k / n) as i64);
            for (dx, dy) in [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)] {
                let (nx, ny) = (x + dx, y + dy);
                if nx < 0 || ny < 0 || nx >= n as i64 || ny >= n as i64 {
                    continue;
                }
                let m = ny as usize * n + nx as usize;
                // Leaving a blocked start is allowed; entering a blocked cell is not
                // (except the goal cell, whose centre may be a few units off the goal).
                if !free[m] && m != g {
                    continue;
                }
                let step = if dx != 0 && dy != 0 { 1414 } else { 1000 };
                let nd = dist[k] + step;
                if nd < dist[m] {
                    dist[m] = nd;
                    prev[m] = k;
                    heap.push(Reverse((nd + h(m), m)));
                }
            }
        }
        if dist[g] == u64::MAX {
            return None;
        }
        let mut cells = vec![g];
        while let Some(&k) = cells.last() {
            if k == s {
                break;
            }
            cells.push(prev[k]);
        }
        cells.reverse();
        // Drop the start and goal cells: the exact start and goal replace them.
        let inner = if cells.len() > 2 { &cells[1..cells.len() - 1] } else { &[][..] };
        let mut raw: Vec<[f64; 2]> = inner.iter().map(|&k| [centre(k % n), centre(k / n)]).collect();
        raw.push(goal);
        Some(self.shorten(start, &raw))
    }

    /// String pulling: from each kept point, jump to the farthest visible waypoint.
    fn shorten(&self, start: [f64; 2], raw: &[[f64; 2]]) -> Vec<[f64; 2]> {
        let mut out = Vec::new();
        let mut from = start;
        let mut i = 0;
        while i < raw.len() {
            let mut j = raw.len() - 1;
            while j > i && !self.segment_free(from, raw[j]) {
                j -= 1;
            }
            out.push(raw[j]);
            from = raw[j];
            i = j + 1;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn path_goes_around_the_block() {
        let shape = TShape::GPC;
        let p = PathPlanner {
            shape: &shape,
            block: Pose2::new(256.0, 256.0, 0.0),
            clearance: 24.0,
            world: 512.0,
        };
        // From above the bar to below the stem: the straight line crosses the T.
        let (a, b) = ([256.0, 150.0], [256.0, 370.0]);
        assert!(!p.segment_free(a, b));
        let path = p.plan(a, b).expect("a path exists");
        assert_eq!(*path.last().unwrap(), b);
        let mut from = a;
        for w in &path {
            assert!(p.segment_free(from, *w), "{from:?} -> {w:?} collides");
            from = *w;
        }
        // A free straight line is returned as is.
        assert_eq!(p.plan([50.0, 50.0], [50.0, 450.0]), Some(vec![[50.0, 450.0]]));
    }
}
