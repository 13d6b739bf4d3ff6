//! An aliased RGB canvas with the three drawing primitives GPC's Push-T renderer uses,
//! with pygame 2.6's pixel rules, so that [`super::gpc_render`] draws the frames GPC's
//! policies and world models were trained on.
//!
//! The rules, found by testing a transcription of them against pygame 2.6.1 on random inputs
//! (300 polygons, 300 lines, 300 disks inside the canvas: every pixel equal), and checked here
//! through whole scenes against GPC's canvases (`super::gpc_render`'s tests):
//! - **Filled polygon**: a scan line per integer row from the lowest to the highest
//!   vertex. Every non-horizontal edge whose row span `[y1, y2)` holds the row (the last
//!   row also takes edges ending on it) gives the crossing
//!   `x1 + floor((y − y1)(x2 − x1) / (y2 − y1))`, the division in single precision;
//!   sorted crossings are filled pairwise, both ends inclusive. Horizontal edges strictly
//!   between the extreme rows are drawn as spans, and a polygon one row high is one span.
//! - **Thick line** (`width` > 1): a Bresenham walk from the first point to the second
//!   (the walk is not symmetric: the order of the points matters); at each step a
//!   run of `width` pixels across the line's minor axis, from `−width/2 + (1 − width mod 2)`
//!   to `+width/2` around the step.
//! - **Filled circle** of integer centre `c` and radius `r`: the midpoint circle, spans
//!   `[c − x, c + x − 1]` on rows `c ± …`, so a disk covers `2r` pixels across, the centre
//!   pixel's right and lower neighbours included.
//!
//! Shapes that leave the canvas are clipped pixel by pixel; pygame clips lines and
//! polygons before walking them, so a shape crossing the canvas border can differ by a
//! few pixels along it (never inside the walls of Push-T).

/// An RGB canvas, row-major, 3 bytes a pixel.
#[derive(Clone, Debug)]
pub struct Canvas {
    side: usize,
    px: Vec<u8>,
}

/// An RGB colour.
pub type Rgb = [u8; 3];

impl Canvas {
    /// A `side × side` canvas filled with `bg`.
    pub fn new(side: usize, bg: Rgb) -> Self {
        Self { side, px: bg.repeat(side * side) }
    }

    /// The canvas side, pixels.
    pub fn side(&self) -> usize {
        self.side
    }

    /// The pixels (row-major RGB).
    pub fn pixels(&self) -> &[u8] {
        &self.px
    }

    /// The pixels, owned.
    pub fn into_pixels(self) -> Vec<u8> {
        self.px
    }

    /// Pixel `(x, y)`.
    pub fn get(&self, x: usize, y: usize) -> Rgb {
        let o = (y * self.side + x) * 3;
        [self.px[o], self.px[o + 1], self.px[o + 2]]
    }

    /// The inclusive span `[x1, x2]` of row `y`, clipped.
    fn hline(&mut self, x1: i64, y: i64, x2: i64, c: Rgb) {
        let n = self.side as i64;
        let (a, b) = (x1.min(x2).max(0), x1.max(x2).min(n - 1));
        if !(0..n).contains(&y) || a > b {
            return;
        }
        let row = y as usize * self.side;
        for x in a as usize..=b as usize {
            self.px[(row + x) * 3..(row + x) * 3 + 3].copy_from_slice(&c);
        }
    }

    /// The inclusive span `[y1, y2]` of column `x`, clipped.
    fn vline(&mut self, x: i64, y1: i64, y2: i64, c: Rgb) {
        let n = self.side as i64;
        let (a, b) = (y1.min(y2).max(0), y1.max(y2).min(n - 1));
        if !(0..n).contains(&x) || a > b {
            return;
        }
        for y in a as usize..=b as usize {
            let o = (y * self.side + x as usize) * 3;
            self.px[o..o + 3].copy_from_slice(&c);
        }
    }

    /// A filled polygon through integer points (closed implicitly; a repeated first
    /// point, as GPC passes, changes nothing).
    pub fn fill_polygon(&mut self, pts: &[[i64; 2]], c: Rgb) {
        let Some(miny) = pts.iter().map(|p| p[1]).min() else { return };
        let maxy = pts.iter().map(|p| p[1]).max().unwrap_or(miny);
        if miny == maxy {
            let minx = pts.iter().map(|p| p[0]).min().unwrap_or(0);
            let maxx = pts.iter().map(|p| p[0]).max().unwrap_or(0);
            self.hline(minx, miny, maxx, c);
            return;
        }
        let n = pts.len();
        let mut xs: Vec<i64> = Vec::with_capacity(n);
        for y in miny..=maxy {
            xs.clear();
            for i in 0..n {
                let (p, q) = (pts[(i + n - 1) % n], pts[i]);
                let ((x1, y1), (x2, y2)) = match p[1].cmp(&q[1]) {
                    std::cmp::Ordering::Less => ((p[0], p[1]), (q[0], q[1])),
                    std::cmp::Ordering::Greater => ((q[0], q[1]), (p[0], p[1])),
                    std::cmp::Ordering::Equal => continue,
                };
                if (y >= y1 && y < y2) || (y == maxy && y2 == maxy) {
                    // Single precision, as pygame computes it; the operands are far
                    // below 2^24, so they are exact in f32.
                    let t = ((y - y1) * (x2 - x1)) as f32 / (y2 - y1) as f32;
                    xs.push(t.floor() as i64 + x1);
                }
            }
            xs.sort_unstable();
            for pair in xs.chunks_exact(2) {
                self.hline(pair[0], y, pair[1], c);
            }
        }
        for i in 0..n {
            let (p, q) = (pts[(i + n - 1) % n], pts[i]);
            if miny < q[1] && p[1] == q[1] && q[1] < maxy {
                self.hline(q[0], q[1], p[0], c);
            }
        }
    }

    /// A line `width` > 1 pixels thick from `a` to `b` (pygame's `draw.line(s)`).
    pub fn thick_line(&mut self, a: [i64; 2], b: [i64; 2], width: i64, c: Rgb) {
        let ([mut x1, mut y1], [x2, y2]) = (a, b);
        let extra = 1 - width % 2;
        let half = width / 2;
        let across_x = (x1 - x2).abs() <= (y1 - y2).abs();
        let (dx, sx) = ((x2 - x1).abs(), if x1 < x2 { 1 } else { -1 });
        let (dy, sy) = ((y2 - y1).abs(), if y1 < y2 { 1 } else { -1 });
        // C's `(dx > dy ? dx : -dy) / 2`, which truncates toward zero.
        let mut err = if dx > dy { dx / 2 } else { -(dy / 2) };
        loop {
            if across_x {
                if y1 == y2 + sy {
                    break;
                }
                self.hline(x1 - half + extra, y1, x1 + half, c);
            } else {
                if x1 == x2 + sx {
                    break;
                }
                self.vline(x1, y1 - half + extra, y1 + half, c);
            }
            let e2 = err;
            if e2 > -dx {
                err -= dy;
                x1 += sx;
            }
            if e2 < dy {
                err += dx;
                y1 += sy;
            }
        }
    }

    /// A filled disk of integer centre and radius (pygame's `draw.circle`, width 0).
    pub fn fill_circle(&mut self, centre: [i64; 2], r: i64, c: Rgb) {
        let [x0, y0] = centre;
        let (mut f, mut ddx, mut ddy, mut x, mut y) = (1 - r, 0, -2 * r, 0, r);
        while x < y {
            if f >= 0 {
                y -= 1;
                ddy += 2;
                f += ddy;
            }
            x += 1;
            ddx += 2;
            f += ddx + 1;
            if f >= 0 {
                self.hline(x0 - x, y0 + y - 1, x0 + x - 1, c);
                self.hline(x0 - x, y0 - y, x0 + x - 1, c);
            }
            self.hline(x0 - y, y0 + x - 1, x0 + y - 1, c);
            self.hline(x0 - y, y0 - x, x0 + y - 1, c);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const K: Rgb = [0, 0, 0];

    /// The canvas as rows of '#' (drawn) and '.' (background).
    fn art(c: &Canvas) -> Vec<String> {
        (0..c.side())
            .map(|y| (0..c.side()).map(|x| if c.get(x, y) == K { '#' } else { '.' }).collect())
            .collect()
    }

    #[test]
    fn a_disk_of_radius_2_covers_four_pixels_across_right_and_below_the_centre() {
        // pygame.draw.circle(s, c, (3, 3), 2) on an 8 x 8 surface, by hand from the loop:
        // x=1: f = -1 -> 2, spans rows 3+1-1=3 and 3-1=2 over [3-2, 3+2-1] = [1, 4]; f >= 0
        // also gives rows 3+2-1=4 and 3-2=1 over [2, 3]. x=2 stops (x < y fails at y=1).
        let mut c = Canvas::new(8, [255; 3]);
        c.fill_circle([3, 3], 2, K);
        assert_eq!(art(&c)[..6], ["........", "..##....", ".####...", ".####...", "..##....", "........"]);
    }

    #[test]
    fn a_four_wide_line_spans_one_left_and_two_right_of_its_path() {
        // Vertical line x = 3 from y = 1 to 3, width 4: half 2, extra 1 -> x in [2, 5].
        let mut c = Canvas::new(8, [255; 3]);
        c.thick_line([3, 1], [3, 3], 4, K);
        assert_eq!(art(&c)[..5], ["........", "..####..", "..####..", "..####..", "........"]);
    }

    #[test]
    fn polygon_crossings_are_floored_and_the_last_row_is_filled() {
        // Triangle (0,0), (4,0), (0,4). Row y: the edge (4,0)-(0,4) crosses at
        // 4 + floor(y(0-4)/4) = 4 - y, the edge (0,4)-(0,0) at 0; so row y spans [0, 4-y].
        // The top edge is horizontal at miny: not drawn separately, row 0 is [0, 4] anyway.
        let mut c = Canvas::new(6, [255; 3]);
        c.fill_polygon(&[[0, 0], [4, 0], [0, 4]], K);
        assert_eq!(art(&c)[..6], ["#####.", "####..", "###...", "##....", "#.....", "......"]);
    }

    #[test]
    fn shapes_leaving_the_canvas_are_clipped_not_wrapped() {
        let mut c = Canvas::new(4, [255; 3]);
        c.fill_circle([0, 0], 3, K);
        c.thick_line([-5, 3], [10, 3], 2, K);
        c.fill_polygon(&[[-10, -10], [1, -10], [1, 1]], K);
        // Nothing panicked, and the far corner was not touched by any wrap-around.
        assert_eq!(c.get(3, 0), [255; 3]);
        assert_eq!(c.get(3, 3), K);
    }
}
