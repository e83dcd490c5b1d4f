//! Calibration files. `.yaml`/`.yml`: an OpenCV FileStorage file, as OpenCV's calibration
//! sample writes it (`cv::FileStorage` reads it), with `view_names` naming the image of each
//! row of `extrinsic_parameters`; `.json`: the whole `Calibration`. Both are
//! read back wherever a camera is expected. Writes are atomic (temporary file, then rename).

use super::{Calibration, Error, StdDev};
use std::path::Path;

/// A number as OpenCV writes doubles: 17 significant digits, exponent with sign and 2 digits.
fn cv_number(v: f64) -> String {
    let s = format!("{v:.16e}");
    let (mantissa, exp) = s.split_once('e').unwrap_or((&s, "0"));
    let e: i32 = exp.parse().unwrap_or(0);
    format!("{mantissa}e{}{:02}", if e < 0 { '-' } else { '+' }, e.abs())
}

fn matrix(name: &str, rows: usize, cols: usize, data: &[f64]) -> String {
    let values: Vec<String> = data.iter().map(|&v| cv_number(v)).collect();
    format!(
        "{name}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n   data: [ {} ]\n",
        values.join(", ")
    )
}

pub fn to_yaml(c: &Calibration) -> String {
    let k: Vec<f64> = c.camera_matrix.iter().flatten().copied().collect();
    let mut s = String::from("%YAML:1.0\n---\n");
    s += &format!("image_width: {}\nimage_height: {}\n", c.image_width, c.image_height);
    s += &matrix("camera_matrix", 3, 3, &k);
    s += &matrix("distortion_coefficients", 1, 5, &c.distortion_coefficients);
    s += &format!("avg_reprojection_error: {}\n", cv_number(c.rms_px));
    if !c.per_view_rms_px.is_empty() {
        s += &matrix("per_view_reprojection_errors", c.per_view_rms_px.len(), 1, &c.per_view_rms_px);
    }
    let sd = &c.std_dev;
    let mut sdv = vec![sd.fx, sd.fy, sd.cx, sd.cy];
    sdv.extend(sd.distortion);
    s += &matrix("std_dev_intrinsics", 9, 1, &sdv);
    if !c.views.is_empty() {
        let ext: Vec<f64> = c.views.iter().flat_map(|v| v.rvec.iter().chain(&v.tvec).copied()).collect();
        s += &matrix("extrinsic_parameters", c.views.len(), 6, &ext);
        // The image each row of extrinsic_parameters belongs to, in the same order (a
        // FileStorage sequence of strings).
        let names: Vec<String> = c
            .views
            .iter()
            .map(|v| format!("\"{}\"", v.name.replace('\\', "\\\\").replace('"', "\\\"")))
            .collect();
        s += &format!("view_names: [ {} ]\n", names.join(", "));
    }
    s
}

/// Writes by extension: `.yaml`/`.yml` or `.json`.
pub fn write(path: &Path, c: &Calibration) -> Result<(), Error> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let text = match ext.as_str() {
        "yaml" | "yml" => to_yaml(c),
        "json" => serde_json::to_string_pretty(c)
            .map_err(|e| Error::File { path: path.into(), message: e.to_string() })?,
        _ => {
            return Err(Error::File {
                path: path.into(),
                message: "expected a file name ending in .yaml, .yml or .json".into(),
            })
        }
    };
    crate::image::io::write_atomically(path, |tmp| std::fs::write(tmp, &text).map_err(|e| e.to_string()))
        .map_err(|e| Error::File { path: path.into(), message: e.to_string() })
}

/// Reads a calibration written by lumen or OpenCV (`.yaml`/`.yml`/`.json`).
pub fn read(path: &Path) -> Result<Calibration, Error> {
    let err = |message: String| Error::File { path: path.into(), message };
    let text = std::fs::read_to_string(path).map_err(|e| err(format!("cannot read: {e}")))?;
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let c = match ext.as_str() {
        "json" => serde_json::from_str::<Calibration>(&text).map_err(|e| err(e.to_string()))?,
        "yaml" | "yml" => from_yaml(&text).map_err(err)?,
        _ => return Err(err("expected a file name ending in .yaml, .yml or .json".into())),
    };
    c.camera().validate().map_err(|m| err(format!("not a usable camera: {m}")))?;
    Ok(c)
}

/// The `data` of an `!!opencv-matrix` named `key`, checked against `rows × cols`.
fn yaml_matrix(text: &str, key: &str, rows: usize, cols: usize) -> Result<Vec<f64>, String> {
    let start = text.find(&format!("{key}:")).ok_or_else(|| format!("no `{key}`"))?;
    let rest = &text[start..];
    let data = rest.find("data:").ok_or_else(|| format!("`{key}` has no `data`"))?;
    let open = rest[data..].find('[').ok_or_else(|| format!("`{key}.data` is not a list"))? + data;
    let close = rest[open..].find(']').ok_or_else(|| format!("`{key}.data` is not closed"))? + open;
    let values: Result<Vec<f64>, String> = rest[open + 1..close]
        .split(',')
        .map(|w| w.trim())
        .filter(|w| !w.is_empty())
        .map(|w| w.parse::<f64>().map_err(|_| format!("`{key}.data` holds '{w}', not a number")))
        .collect();
    let values = values?;
    if values.len() != rows * cols {
        return Err(format!("`{key}` has {} values, expected {rows}×{cols}", values.len()));
    }
    Ok(values)
}

fn yaml_scalar(text: &str, key: &str) -> Option<f64> {
    text.lines().find_map(|l| l.trim().strip_prefix(&format!("{key}:")).and_then(|v| v.trim().parse().ok()))
}

fn from_yaml(text: &str) -> Result<Calibration, String> {
    if !text.trim_start().starts_with("%YAML") {
        return Err("not an OpenCV FileStorage YAML file (no %YAML header)".into());
    }
    let k = yaml_matrix(text, "camera_matrix", 3, 3)?;
    // OpenCV writes 1×5 (or 5×1, or with more terms); lumen's model uses the first five.
    let d = yaml_matrix(text, "distortion_coefficients", 1, 5)
        .or_else(|_| yaml_matrix(text, "distortion_coefficients", 5, 1))?;
    let size = |key: &str| -> Result<u32, String> {
        yaml_scalar(text, key)
            .filter(|v| *v >= 1.0 && v.fract() == 0.0)
            .map(|v| v as u32)
            .ok_or_else(|| format!("no positive integer `{key}`"))
    };
    Ok(Calibration {
        image_width: size("image_width")?,
        image_height: size("image_height")?,
        camera_matrix: [[k[0], k[1], k[2]], [k[3], k[4], k[5]], [k[6], k[7], k[8]]],
        distortion_coefficients: [d[0], d[1], d[2], d[3], d[4]],
        rms_px: yaml_scalar(text, "avg_reprojection_error").unwrap_or(f64::NAN),
        per_view_rms_px: Vec::new(),
        std_dev: StdDev { fx: 0.0, fy: 0.0, cx: 0.0, cy: 0.0, distortion: [0.0; 5] },
        views: Vec::new(),
        skipped: Vec::new(),
        conditioning: Default::default(),
        larger_grids: Vec::new(),
    })
}
