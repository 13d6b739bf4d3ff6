//! A hand-written judge of frames: how high a coloured object stands in the image.
//!
//! Lift's cube is the only red thing on the table, and robosuite's agentview looks
//! down at it from the front, so a lifted cube moves up the frame. The rule finds
//! the red pixels (red above twice green and twice blue, and 40 above green), takes
//! the median row of those below `top_row` (the robot's few red pixels sit at the
//! top of the frame, and show when the fingers hide the cube), and calls the frame a
//! success when at least `min_pixels` of them are found and their median row is at
//! or above `success_row` (rows count from the top). The score is 1 or 0.
//!
//! It is measured beside the learned judge (`read-judge --rule lift-red`), as the
//! Lift task asks: a rule needs no training, reads any frame size it was set for,
//! and cannot be fooled by a texture a network latched onto, but it knows nothing of
//! a cube held at 3 cm against one at 5.

use harness::judge::Judge;
use serde::{Deserialize, Serialize};

/// The colour-height rule's parameters (`judge.json`'s `rule`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColourHeight {
    /// Frame side the rows refer to.
    pub image_size: usize,
    /// Red pixels above this row (smaller index) are ignored.
    pub top_row: usize,
    /// A frame with fewer red pixels (below `top_row`) shows no object: score 0.
    pub min_pixels: usize,
    /// Success when the red pixels' median row is at most this row.
    pub success_row: usize,
}

impl ColourHeight {
    /// Lift's red cube above row 40 of the 96 × 96 agentview, about 10 px above where
    /// it rests (`read-judge --rule lift-red`). Set from the training episodes of
    /// `lift_ne_10000.zarr` (seeds 10000+): the cube's median row is 46–53 at rest and
    /// 29–35 once lifted; the fingers can hide all but one red pixel, and the robot's
    /// own red shows above row 16.
    pub fn lift_red() -> Self {
        Self { image_size: 96, top_row: 16, min_pixels: 6, success_row: 40 }
    }
}

/// Whether an RGB pixel is the object's red.
fn is_red(r: u8, g: u8, b: u8) -> bool {
    let (r, g, b) = (u16::from(r), u16::from(g), u16::from(b));
    r > 2 * g && r > 2 * b && r > g + 40
}

impl ColourHeight {
    /// The red pixels' median row below `top_row`, with their count; `None` for a frame
    /// of another size.
    pub fn median_row(&self, frame: &[u8]) -> Option<(usize, usize)> {
        let s = self.image_size;
        if frame.len() != s * s * 3 {
            return None;
        }
        let rows: Vec<usize> = frame
            .chunks_exact(3)
            .enumerate()
            .filter(|&(p, px)| p / s >= self.top_row && is_red(px[0], px[1], px[2]))
            .map(|(p, _)| p / s)
            .collect();
        // Rows come in increasing order, so the middle one is the median.
        Some((rows.get(rows.len() / 2).copied().unwrap_or(s), rows.len()))
    }
}

impl Judge for ColourHeight {
    fn score(&self, frame: &[u8]) -> f64 {
        match self.median_row(frame) {
            None => f64::NAN,
            Some((row, n)) => f64::from(u8::from(n >= self.min_pixels && row <= self.success_row)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 96 x 96 grey frame with a red block over `rows` x columns 40..44.
    fn frame(rows: std::ops::Range<usize>) -> Vec<u8> {
        let mut f = vec![200u8; 96 * 96 * 3];
        for y in rows {
            for x in 40..44 {
                f[(y * 96 + x) * 3..(y * 96 + x) * 3 + 3].copy_from_slice(&[186, 62, 73]);
            }
        }
        f
    }

    #[test]
    fn a_red_block_counts_when_high_enough() {
        let rule = ColourHeight::lift_red();
        // Rows 46..49 (12 pixels): median row 47 (the 7th of 46,46,46,46,47,47,...) > 40: 0.
        assert_eq!(rule.median_row(&frame(46..49)), Some((47, 12)));
        assert_eq!(rule.score(&frame(46..49)), 0.0);
        // Rows 30..33: median 31 <= 40: 1.
        assert_eq!(rule.score(&frame(30..33)), 1.0);
        // One row of 4 pixels (< 6): no object, 0; above row 16 it is ignored: 0 pixels.
        assert_eq!(rule.score(&frame(30..31)), 0.0);
        assert_eq!(rule.median_row(&frame(5..10)), Some((96, 0)));
        // Dark red faces count as red: 74 > 2 * 25, 74 > 2 * 29, 74 > 25 + 40.
        assert!(is_red(74, 25, 29) && !is_red(200, 200, 200) && !is_red(120, 90, 90));
        // A frame of another size scores nothing.
        assert!(rule.score(&[0u8; 12]).is_nan());
    }
}
