//! Overlay images for `lumen calibrate --debug DIR`: what the detector saw in each view.
//!
//! A found board is drawn as OpenCV's `drawChessboardCorners` draws it: a ring on every
//! corner, the corners of a row joined in order, each row in its own colour, so a flipped or
//! shifted ordering shows at a glance; corner 0 gets a second, larger ring. A view without a
//! whole board shows the chessboard-like corners that were found (red crosses), so the reason
//! printed for it can be checked against the image. Drawing is a few rings and segments,
//! written here rather than pulling in an imaging crate for them.

use super::detect::{self, BoardSize};
use crate::image::filter::Grey;
use glam::DVec2;

/// Row colours, cycled (OpenCV's palette order: red, orange, yellow, green, cyan, blue, violet).
const ROW_COLOURS: [[u8; 3]; 7] =
    [[255, 0, 0], [255, 128, 0], [230, 200, 0], [0, 200, 0], [0, 200, 200], [0, 80, 255], [200, 0, 255]];

/// An 8-bit RGB canvas holding the grey image.
pub struct Canvas {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
}

impl Canvas {
    fn from_grey(img: &Grey) -> Canvas {
        let rgb = img
            .data
            .iter()
            .flat_map(|&v| {
                let c = (v.clamp(0.0, 1.0) * 255.0).round() as u8;
                [c, c, c]
            })
            .collect();
        Canvas { width: img.width as u32, height: img.height as u32, rgb }
    }

    fn dot(&mut self, p: DVec2, colour: [u8; 3]) {
        let (x, y) = (p.x.round(), p.y.round());
        if x >= 0.0 && y >= 0.0 && x < self.width as f64 && y < self.height as f64 {
            let i = 3 * (y as usize * self.width as usize + x as usize);
            self.rgb[i..i + 3].copy_from_slice(&colour);
        }
    }

    fn segment(&mut self, a: DVec2, b: DVec2, colour: [u8; 3]) {
        let steps = (a.distance(b) * 2.0).ceil().max(1.0) as usize;
        for k in 0..=steps {
            self.dot(a.lerp(b, k as f64 / steps as f64), colour);
        }
    }

    fn ring(&mut self, c: DVec2, radius: f64, colour: [u8; 3]) {
        let steps = (radius * 16.0).ceil() as usize;
        for k in 0..steps {
            let t = std::f64::consts::TAU * k as f64 / steps as f64;
            self.dot(c + radius * DVec2::new(t.cos(), t.sin()), colour);
        }
    }

    fn cross(&mut self, c: DVec2, half: f64, colour: [u8; 3]) {
        self.segment(c - DVec2::splat(half), c + DVec2::splat(half), colour);
        self.segment(c + DVec2::new(-half, half), c + DVec2::new(half, -half), colour);
    }
}

/// The overlay of one view: `corners` as `detect` returned them, or `None` for a view without a
/// whole board (its candidate corners are drawn instead).
pub fn draw(img: &Grey, board: BoardSize, corners: Option<&[DVec2]>) -> Canvas {
    let mut canvas = Canvas::from_grey(img);
    match corners {
        Some(pts) => {
            for (row, line) in pts.chunks(board.cols.max(1)).enumerate() {
                let colour = ROW_COLOURS[row % ROW_COLOURS.len()];
                for pair in line.windows(2) {
                    canvas.segment(pair[0], pair[1], colour);
                }
                // The step from the previous row's last corner, as OpenCV draws it.
                if row > 0 {
                    canvas.segment(pts[row * board.cols - 1], line[0], colour);
                }
                for &p in line {
                    canvas.ring(p, 4.0, colour);
                }
            }
            if let Some(&first) = pts.first() {
                canvas.ring(first, 7.0, ROW_COLOURS[0]);
            }
        }
        None => {
            for p in detect::corner_candidates(img, &img.blur(1.0)) {
                canvas.cross(p, 3.0, [255, 0, 0]);
            }
        }
    }
    canvas
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_are_coloured_and_misses_show_candidates() {
        let img = Grey { width: 40, height: 30, data: vec![0.5; 1200] };
        let board = BoardSize { cols: 3, rows: 2 };
        let pts: Vec<DVec2> =
            (0..6).map(|k| DVec2::new(10.0 + 8.0 * (k % 3) as f64, 10.0 + 10.0 * (k / 3) as f64)).collect();
        let c = draw(&img, board, Some(&pts));
        let at = |x: usize, y: usize| &c.rgb[3 * (y * 40 + x)..3 * (y * 40 + x) + 3];
        // Between corners 0 and 1 (row 0, red) and between 3 and 4 (row 1, orange).
        assert_eq!(at(14, 10), &ROW_COLOURS[0]);
        assert_eq!(at(14, 20), &ROW_COLOURS[1]);
        // Away from everything: the grey image.
        assert_eq!(at(35, 3), &[128, 128, 128]);
        // A flat image has no candidates: nothing drawn.
        let miss = draw(&img, board, None);
        assert!(miss.rgb.iter().all(|&v| v == 128));
    }
}
