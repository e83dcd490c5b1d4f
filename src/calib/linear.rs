//! Code values made linear through the camera's response before the corners are refined.
//!
//! A chessboard corner is the point where the edges between bright and dark squares cross.
//! On code values written through a non-linear response (a JPEG's sRGB curve, a gamma), the
//! blur of the lens and the pixel's area are no longer a linear mix of the two squares: a
//! partly covered edge pixel reads brighter than its share, every edge moves towards its dark
//! side, and at a foreshortened corner the four moves do not cancel. The bias does not average
//! out over views: it moves the principal point (docs/measurements.md, Calibration, has the
//! figures).
//!
//! The detector finds the board on the codes as they are (`detect::find`: candidates, grid,
//! order, where the bias of a fraction of a pixel does not matter), then refines each corner
//! on the codes made linear (`DetectOptions::response`), where it is found where a linear
//! sensor would put it. The response is the one the user assumes (`lumen calibrate
//! --response`; a case's `response`): the sRGB curve for most JPEGs, a gamma, or linear (the
//! codes as they are, as OpenCV takes them). A grey view's value is the mean of its channels'
//! codes, made linear as one: for a neutral board the channels nearly agree, and
//! f⁻¹(mean) differs from the mean of f⁻¹ by ½·f⁻¹''·(their variance). The inverse is
//! tabulated at `TABLE` + 1 points and interpolated linearly: on gamma 2.2 the interpolation
//! error is at most h²/8·max|f⁻¹''| = 2.64/(8·4096²) = 2·10⁻⁸ of full scale, far under an 8- or
//! 16-bit code's step.

use super::Error;
use crate::image::filter::Grey;
use crate::render::sensor::Response;

/// Intervals of the inverse response's table.
const TABLE: usize = 4096;

/// Each value (a fraction of full scale; clamped to [0, 1]) made linear through the green
/// channel's inverse response.
pub fn linearise(img: &Grey, response: &Response) -> Grey {
    if *response == Response::Linear {
        return img.clone();
    }
    let table: Vec<f32> = (0..=TABLE).map(|i| response.inverse(i as f64 / TABLE as f64) as f32).collect();
    let data = img
        .data
        .iter()
        .map(|&v| {
            let x = v.clamp(0.0, 1.0) * TABLE as f32;
            let i = (x as usize).min(TABLE - 1);
            table[i] + (x - i as f32) * (table[i + 1] - table[i])
        })
        .collect();
    Grey { data, ..*img }
}

/// Refuses a non-linear response for an OpenEXR file, whose values are linear already: the
/// curve would bend them, and clip every value above 1.
pub fn check_codes(path: &std::path::Path, response: &Response) -> Result<(), Error> {
    let exr = path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    if exr && *response != Response::Linear {
        return Err(Error::BadInput(format!(
            "{}: an OpenEXR image holds linear values, not codes; the response {response:?} applies to the codes of a PNG, JPEG or TIFF (use linear)",
            path.display()
        )));
    }
    Ok(())
}

/// `--response`'s values: `linear`, `srgb` or `gamma:G` (G from 0.1 to 10, the exponent the
/// codes were raised to the reciprocal of).
pub fn parse_response(s: &str) -> Result<Response, Error> {
    let expected = "expected linear, srgb or gamma:G (G from 0.1 to 10, e.g. gamma:2.2)";
    let r = match s.trim().to_ascii_lowercase().as_str() {
        "linear" => Response::Linear,
        "srgb" => Response::Srgb,
        other => match other.strip_prefix("gamma:").map(|g| g.trim().parse::<f64>()) {
            Some(Ok(gamma)) => Response::Gamma { gamma },
            _ => return Err(Error::BadInput(format!("response \"{s}\": {expected}"))),
        },
    };
    r.validate().map_err(|e| Error::BadInput(format!("response \"{s}\": {e}; {expected}")))?;
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Linear leaves the values alone; a gamma-2.2 code goes back to the exposure that made
    /// it, within the table's interpolation error; values beyond full scale are clamped.
    #[test]
    fn codes_go_back_to_exposure() {
        let img = Grey { width: 3, height: 1, data: vec![0.1, 0.5, 1.0] };
        assert_eq!(linearise(&img, &Response::Linear).data, img.data);
        let gamma = Response::Gamma { gamma: 2.2 };
        for x in [0.0, 1e-4, 0.01, 0.18, 0.5, 0.9, 1.0f64] {
            let one = Grey { width: 1, height: 1, data: vec![gamma.apply(x) as f32] };
            let back = linearise(&one, &gamma).data[0] as f64;
            assert!((back - x).abs() < 1e-6, "{x}: {back}");
        }
        for y in [0.0, 0.02, 0.04045, 0.3, 1.0f64] {
            let one = Grey { width: 1, height: 1, data: vec![y as f32] };
            let back = linearise(&one, &Response::Srgb).data[0] as f64;
            let want = if y <= 0.04045 { y / 12.92 } else { ((y + 0.055) / 1.055).powf(2.4) };
            assert!((back - want).abs() < 1e-6, "{y}: {back}");
        }
        let outside = Grey { width: 2, height: 1, data: vec![-0.5, 1.5] };
        assert_eq!(linearise(&outside, &Response::Srgb).data, vec![0.0, 1.0]);
    }

    #[test]
    fn response_names() {
        assert_eq!(parse_response("sRGB").ok(), Some(Response::Srgb));
        assert_eq!(parse_response("linear").ok(), Some(Response::Linear));
        assert_eq!(parse_response("gamma:2.2").ok(), Some(Response::Gamma { gamma: 2.2 }));
        for bad in ["gamma:0", "gamma:nan", "gamma:", "gamma", "log", ""] {
            let e = parse_response(bad).unwrap_err();
            assert_eq!(e.fault(), crate::Fault::BadInput);
            let e = e.to_string();
            assert!(e.contains("expected linear, srgb or gamma:G"), "{bad}: {e}");
        }
    }
}
