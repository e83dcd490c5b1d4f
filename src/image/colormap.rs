//! False colour for scalar images a person looks at (angular error, depth): viridis
//! (perceptually uniform, ordered in lightness, so it reads in grey and for colour-blind
//! eyes; plotters' table) with a colour bar that carries the scale, labelled in a small
//! hand-drawn pixel font (digits and a few signs are all a scale needs, and a font file or a
//! text renderer would be a dependency for ten glyphs).

use plotters::style::colors::colormaps::ViridisRGB;

/// Viridis at `t` in [0, 1] (clamped; NaN gives the low end).
pub fn viridis(t: f64) -> [u8; 3] {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let c = ViridisRGB::get_color(t);
    [c.0, c.1, c.2]
}

/// The smallest of 1, 2 or 5 × 10^k at or above `v` (for a scale's upper end); `v` ≤ 0 or not
/// finite gives 1.
pub fn nice_ceiling(v: f64) -> f64 {
    if !(v.is_finite() && v > 0.0) {
        return 1.0;
    }
    let p = 10f64.powf(v.log10().floor());
    [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * p).find(|&c| c >= v * (1.0 - 1e-12)).unwrap_or(10.0 * p)
}

/// A label for a scale's end: `12`, `2.5`, `0.003`, `1.2e5`.
pub fn label(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 || (1e-3..1e5).contains(&a) {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.1e}")
    }
}

/// 3×5 glyphs, one row of three bits per entry, top row first.
fn glyph(c: char) -> [u8; 5] {
    match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        '.' => [0, 0, 0, 0, 2],
        '-' => [0, 0, 7, 0, 0],
        '+' => [0, 2, 7, 2, 0],
        'e' => [7, 4, 7, 4, 7],
        '°' => [2, 5, 2, 0, 0],
        'm' => [0, 0, 7, 7, 5],
        _ => [0; 5],
    }
}

/// Draws `text` in white into an RGB8 buffer of width `w` with its top-left at (x, y), each
/// font pixel `s`×`s`.
fn draw_text(rgb: &mut [u8], w: usize, x: usize, y: usize, s: usize, text: &str) {
    draw_text_in(rgb, w, x, y, s, text, [255; 3]);
}

/// Draws `text` in `colour` (digits and the signs of `glyph`), as `draw_text` does.
pub(crate) fn draw_text_in(
    rgb: &mut [u8],
    w: usize,
    x: usize,
    y: usize,
    s: usize,
    text: &str,
    colour: [u8; 3],
) {
    let h = rgb.len() / (3 * w);
    for (k, c) in text.chars().enumerate() {
        for (row, bits) in glyph(c).iter().enumerate() {
            for col in 0..3 {
                if bits & (4 >> col) == 0 {
                    continue;
                }
                for dy in 0..s {
                    for dx in 0..s {
                        let (px, py) = (x + (4 * k + col) * s + dx, y + row * s + dy);
                        if px < w && py < h {
                            rgb[3 * (py * w + px)..3 * (py * w + px) + 3].copy_from_slice(&colour);
                        }
                    }
                }
            }
        }
    }
}

/// `rgb` (width × height, RGB8) with a colour bar to its right: viridis from `low` at the
/// bottom to `high` at the top, labelled at both ends. Returns the new buffer and its size
/// (the panel is at least 64 pixels tall, so a small image grows downwards in black).
pub fn with_colour_bar(rgb: &[u8], width: u32, height: u32, low: &str, high: &str) -> (Vec<u8>, u32, u32) {
    let (w, h) = (width as usize, height as usize);
    let out_h = h.max(64);
    let s = (out_h / 160).clamp(1, 4);
    let chars = low.chars().count().max(high.chars().count());
    let (gap, bar) = (4 * s, 6 * s);
    let panel = gap + bar + 2 * s + 4 * s * chars + 2 * s;
    let out_w = w + panel;
    let mut out = vec![0u8; 3 * out_w * out_h];
    for y in 0..h {
        out[3 * y * out_w..3 * y * out_w + 3 * w].copy_from_slice(&rgb[3 * y * w..3 * (y + 1) * w]);
    }
    // The bar runs from 3 font pixels below the top to 3 above the bottom, so the end labels
    // sit level with its ends.
    let (top, bottom) = (2 * s, out_h - 2 * s);
    for y in top..bottom {
        let t = (bottom - 1 - y) as f64 / (bottom - 1 - top).max(1) as f64;
        let c = viridis(t);
        for x in w + gap..w + gap + bar {
            out[3 * (y * out_w + x)..3 * (y * out_w + x) + 3].copy_from_slice(&c);
        }
    }
    let tx = w + gap + bar + 2 * s;
    draw_text(&mut out, out_w, tx, top, s, high);
    draw_text(&mut out, out_w, tx, bottom - 5 * s, s, low);
    (out, out_w as u32, out_h as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_ends_and_labels() {
        assert_eq!(nice_ceiling(1.7), 2.0);
        assert_eq!(nice_ceiling(2.0), 2.0);
        assert_eq!(nice_ceiling(3.1), 5.0);
        assert_eq!(nice_ceiling(17.0), 20.0);
        assert_eq!(nice_ceiling(0.03), 0.05);
        assert_eq!(nice_ceiling(f64::NAN), 1.0);
        assert_eq!(label(20.0), "20");
        assert_eq!(label(2.5), "2.5");
        assert_eq!(label(0.0), "0");
        assert_eq!(label(123456.0), "1.2e5");
        assert_eq!(viridis(0.0), [68, 1, 84]);
        assert_eq!(viridis(1.0), [254, 232, 37]);
        assert_eq!(viridis(f64::NAN), viridis(0.0));
    }

    #[test]
    fn the_bar_runs_from_low_at_the_bottom_to_high_at_the_top() {
        let img = vec![10u8; 3 * 8 * 4];
        let (out, w, h) = with_colour_bar(&img, 8, 4, "0°", "20°");
        assert_eq!(h, 64);
        assert_eq!(out.len(), (3 * w * h) as usize);
        // The image is kept; below it the panel is black.
        assert_eq!(&out[..3], &[10, 10, 10]);
        assert_eq!(&out[3 * (10 * w as usize)..3 * (10 * w as usize) + 3], &[0, 0, 0]);
        let bar_x = 8 + 4;
        let at = |y: usize| {
            let i = 3 * (y * w as usize + bar_x);
            [out[i], out[i + 1], out[i + 2]]
        };
        assert_eq!(at(2), viridis(1.0));
        assert_eq!(at(h as usize - 3), viridis(0.0));
        // Some label pixels are white.
        assert!(out.chunks(3).any(|p| p == [255, 255, 255]));
    }
}
