//! The `--debug` overlay of `lumen color detect`: the photograph with the found cell grid
//! (yellow), each patch's sampled square (the central half of its cell, as `color fit`
//! samples it; cyan) and its number in chart order (1 "dark skin" … 24 "black 2"), so the
//! corners, the orientation and the sampled areas can be checked by eye.

use super::Detection;
use crate::image::Image;

/// The overlay as RGB8 (width, height, bytes).
pub fn draw(image: &Image, linear: bool, det: &Detection) -> (u32, u32, Vec<u8>) {
    let (w, h) = (image.width as usize, image.height as usize);
    let exposure = if linear { super::regions::exposures(image).first().copied() } else { None };
    let enc = super::regions::Encoded::new(image, exposure);
    let mut rgb = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        for x in 0..w {
            // Dimmed, so the drawing stands out.
            rgb.extend(enc.pixel(x, y).map(|v| (v * 0.7 * 255.0 + 0.5) as u8));
        }
    }
    let thick = (w.max(h) / 600).max(1);
    let mut line = |a: [f64; 2], b: [f64; 2], colour: [u8; 3]| {
        let n = ((b[0] - a[0]).abs().max((b[1] - a[1]).abs()).ceil() as usize).clamp(1, 20_000);
        for i in 0..=n {
            let t = i as f64 / n as f64;
            let (x, y) = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]));
            for dy in 0..thick {
                for dx in 0..thick {
                    let (px, py) = ((x.round() as i64) + dx as i64, (y.round() as i64) + dy as i64);
                    if px >= 0 && py >= 0 && (px as usize) < w && (py as usize) < h {
                        let o = 3 * (py as usize * w + px as usize);
                        rgb[o..o + 3].copy_from_slice(&colour);
                    }
                }
            }
        }
    };
    let at = |u: f64, v: f64| det.to_image(image.width, image.height, u, v);
    for u in 0..=6 {
        line(at(u as f64, 0.0), at(u as f64, 4.0), [255, 220, 0]);
    }
    for v in 0..=4 {
        line(at(0.0, v as f64), at(6.0, v as f64), [255, 220, 0]);
    }
    let (lo, hi) = (
        0.5 - crate::color::chart::SAMPLED_FRACTION / 2.0,
        0.5 + crate::color::chart::SAMPLED_FRACTION / 2.0,
    );
    for k in 0..24 {
        let (c, r) = ((k % 6) as f64, (k / 6) as f64);
        let sq = [(lo, lo), (hi, lo), (hi, hi), (lo, hi)].map(|(a, b)| at(c + a, r + b));
        for i in 0..4 {
            line(sq[i], sq[(i + 1) % 4], [0, 230, 255]);
        }
    }
    // Corner 0 (by "dark skin") marked by a short diagonal into the grid.
    line(at(0.0, 0.0), at(0.3, 0.3), [255, 60, 60]);
    for k in 0..24 {
        let centre = at((k % 6) as f64 + 0.5, (k / 6) as f64 + 0.5);
        let pitch = {
            let (a, b) = (at(0.0, 0.0), at(6.0, 0.0));
            ((b[0] - a[0]).hypot(b[1] - a[1]) / 6.0).max(1.0)
        };
        let s = ((pitch / 40.0) as usize).max(1);
        let text = (k + 1).to_string();
        let (tw, th) = ((4 * text.len() - 1) * s, 5 * s);
        let (x, y) = (centre[0] - tw as f64 / 2.0, centre[1] - th as f64 / 2.0);
        if x >= 0.0 && y >= 0.0 {
            crate::image::colormap::draw_text_in(
                &mut rgb,
                w,
                x as usize,
                y as usize,
                s,
                &text,
                [255, 255, 255],
            );
        }
    }
    (w as u32, h as u32, rgb)
}
