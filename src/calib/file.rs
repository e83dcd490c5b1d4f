//! Calibration files. `.yaml`/`.yml`: an OpenCV FileStorage file, as OpenCV's calibration
//! sample writes it (`cv::FileStorage` reads it), with `view_names` naming the image of each
//! row of `extrinsic_parameters`; `.json`: the whole `Calibration`. Both are
//! read back wherever a camera is expected. Writes are atomic (temporary file, then rename).

use super::{Calibration, Error, StdDev};
use crate::error::Invalid;
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
    crate::image::io::write_atomically(path, |tmp| std::fs::write(tmp, &text)).map_err(|e| {
        let message = match e {
            crate::image::io::Error::Write { message, .. } => format!("cannot write: {message}"),
            other => other.to_string(),
        };
        Error::Io { path: path.into(), message }
    })
}

/// Reads a calibration written by lumen or OpenCV (`.yaml`/`.yml`/`.json`).
pub fn read(path: &Path) -> Result<Calibration, Error> {
    let err = |message: String| Error::File { path: path.into(), message };
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::Io { path: path.into(), message: format!("cannot read: {e}") })?;
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let c = match ext.as_str() {
        "json" => serde_json::from_str::<Calibration>(&text).map_err(|e| err(e.to_string()))?,
        "yaml" | "yml" => from_yaml(&text).map_err(|e| err(e.0))?,
        _ => return Err(err("expected a file name ending in .yaml, .yml or .json".into())),
    };
    let k = &c.camera_matrix;
    if k[0][1] != 0.0 {
        return Err(err(format!("`camera_matrix` has a skew of {}: lumen's camera model has none", k[0][1])));
    }
    if k[1][0] != 0.0 || k[2] != [0.0, 0.0, 1.0] {
        return Err(err(format!(
            "`camera_matrix` rows 2 and 3 are {:?}, {:?}: expected [0, fy, cy], [0, 0, 1]",
            k[1], k[2]
        )));
    }
    c.camera().validate().map_err(|m| err(format!("not a usable camera: {m}")))?;
    Ok(c)
}

/// The subset of OpenCV FileStorage YAML a calibration needs, read by structure rather than
/// by searching the text: `#` comments are dropped; top-level keys (no indentation) are
/// `key: scalar` or `key: !!opencv-matrix` followed by its indented `rows`, `cols`, `dt` and
/// `data: [ … ]` (the list may run over several lines); a key given twice is refused, as are
/// sequences, mappings and anything else lumen does not read (they are skipped only when their
/// key is not one lumen needs).
struct FileStorage {
    /// Top-level key → its value text (after the colon) and, for a matrix, its block's lines.
    entries: Vec<(String, String, Vec<String>)>,
}

impl FileStorage {
    fn parse(text: &str) -> Result<FileStorage, Invalid> {
        let mut entries: Vec<(String, String, Vec<String>)> = Vec::new();
        for (n, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or("").trim_end();
            if line.trim().is_empty() || line.starts_with('%') || line.trim() == "---" {
                continue;
            }
            if line.starts_with([' ', '\t']) {
                match entries.last_mut() {
                    Some(last) => last.2.push(line.trim().to_string()),
                    None => return Err(format!("line {}: indented before any key", n + 1).into()),
                }
                continue;
            }
            let Some((key, value)) = line.split_once(':') else {
                return Err(format!("line {}: expected `key: value`", n + 1).into());
            };
            let key = key.trim().to_string();
            if entries.iter().any(|e| e.0 == key) {
                return Err(format!("`{key}` is given twice (line {})", n + 1).into());
            }
            entries.push((key, value.trim().to_string(), Vec::new()));
        }
        Ok(FileStorage { entries })
    }

    fn get(&self, key: &str) -> Option<&(String, String, Vec<String>)> {
        self.entries.iter().find(|e| e.0 == key)
    }

    fn scalar(&self, key: &str) -> Option<f64> {
        self.get(key).and_then(|e| e.1.parse().ok())
    }

    /// An `!!opencv-matrix`: (rows, cols, data in row order).
    fn matrix(&self, key: &str) -> Result<(usize, usize, Vec<f64>), Invalid> {
        let (_, tag, block) = self.get(key).ok_or_else(|| Invalid(format!("no `{key}`")))?;
        if tag != "!!opencv-matrix" {
            return Err(format!("`{key}` is `{tag}`, expected an !!opencv-matrix").into());
        }
        let field =
            |name: &str| block.iter().find_map(|l| l.strip_prefix(&format!("{name}:")).map(str::trim));
        let count = |name: &str| -> Result<usize, Invalid> {
            field(name)
                .and_then(|v| v.parse().ok())
                .filter(|&v: &usize| v >= 1)
                .ok_or_else(|| Invalid(format!("`{key}` has no positive `{name}`")))
        };
        let (rows, cols) = (count("rows")?, count("cols")?);
        let at = block
            .iter()
            .position(|l| l.starts_with("data:"))
            .ok_or_else(|| Invalid(format!("`{key}` has no `data`")))?;
        let list = block[at..].join(" ");
        let open = list.find('[').ok_or_else(|| Invalid(format!("`{key}.data` is not a list")))?;
        let close = list.find(']').ok_or_else(|| Invalid(format!("`{key}.data` is not closed")))?;
        let values = list[open + 1..close]
            .split(',')
            .map(str::trim)
            .filter(|w| !w.is_empty())
            .map(|w| w.parse::<f64>().map_err(|_| Invalid(format!("`{key}.data` holds '{w}', not a number"))))
            .collect::<Result<Vec<f64>, Invalid>>()?;
        if values.len() != rows * cols {
            return Err(
                format!("`{key}` has {} values, but rows × cols = {rows}×{cols}", values.len()).into()
            );
        }
        Ok((rows, cols, values))
    }
}

fn from_yaml(text: &str) -> Result<Calibration, Invalid> {
    if !text.trim_start().starts_with("%YAML") {
        return Err("not an OpenCV FileStorage YAML file (no %YAML header)".into());
    }
    let fs = FileStorage::parse(text)?;
    let (rows, cols, k) = fs.matrix("camera_matrix")?;
    if (rows, cols) != (3, 3) {
        return Err(format!("`camera_matrix` is {rows}×{cols}, expected 3×3").into());
    }
    // OpenCV writes 4, 5, 8, 12 or 14 coefficients: k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 … s4 [τx τy]]]].
    // lumen's model is k1 k2 p1 p2 k3: the rational, thin-prism and tilt terms must be zero.
    let (rows, cols, d) = fs.matrix("distortion_coefficients")?;
    if rows.min(cols) != 1 || ![4, 5, 8, 12, 14].contains(&d.len()) {
        return Err(format!(
            "`distortion_coefficients` is {rows}×{cols}: expected a row or column of 4, 5, 8, 12 or 14 (OpenCV's models)"
        ).into());
    }
    if d.iter().skip(5).any(|v| *v != 0.0) {
        return Err(format!(
            "`distortion_coefficients` has {} terms, and those after k3 (rational k4–k6, thin prism s1–s4, tilt τx, τy) are not zero: lumen's model has k1, k2, p1, p2, k3 only",
            d.len()
        ).into());
    }
    let mut five = [0.0; 5];
    five[..d.len().min(5)].copy_from_slice(&d[..d.len().min(5)]);
    let size = |key: &str| -> Result<u32, Invalid> {
        let v = fs.scalar(key).ok_or_else(|| Invalid(format!("no number `{key}`")))?;
        if v >= 1.0 && v.fract() == 0.0 && v <= 1e6 {
            Ok(v as u32)
        } else {
            Err(format!("`{key}: {v}`: expected a whole number of pixels from 1 to 1000000").into())
        }
    };
    Ok(Calibration {
        image_width: size("image_width")?,
        image_height: size("image_height")?,
        camera_matrix: [[k[0], k[1], k[2]], [k[3], k[4], k[5]], [k[6], k[7], k[8]]],
        distortion_coefficients: five,
        rms_px: fs.scalar("avg_reprojection_error").unwrap_or(f64::NAN),
        per_view_rms_px: Vec::new(),
        std_dev: StdDev { fx: 0.0, fy: 0.0, cx: 0.0, cy: 0.0, distortion: [0.0; 5] },
        views: Vec::new(),
        skipped: Vec::new(),
        conditioning: Default::default(),
        larger_grids: Vec::new(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn yaml(k: &str, d: &str, extra: &str) -> String {
        format!(
            "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n{extra}camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ {k} ]\ndistortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: {}\n   dt: d\n   data: [ {d} ]\n",
            d.split(',').count()
        )
    }
    const K: &str = "500., 0., 320., 0., 500., 240., 0., 0., 1.";

    /// What OpenCV writes is read; what lumen cannot represent is refused by name.
    #[test]
    fn opencv_yaml_is_read_by_structure() {
        let ok = from_yaml(&yaml(K, "-0.1, 0.01, 0., 0., 0.", "")).unwrap();
        assert_eq!(ok.distortion_coefficients, [-0.1, 0.01, 0.0, 0.0, 0.0]);
        // Four coefficients (k3 = 0), and eight whose rational terms are zero.
        assert!(from_yaml(&yaml(K, "-0.1, 0.01, 0., 0.", "")).is_ok());
        assert!(from_yaml(&yaml(K, "-0.1, 0.01, 0., 0., 0.001, 0., 0., 0.", "")).is_ok());
        let e = from_yaml(&yaml(K, "-0.1, 0.01, 0., 0., 0.001, 0.2, 0., 0.", "")).unwrap_err().0;
        assert!(e.contains("8 terms") && e.contains("rational"), "{e}");
        let e = from_yaml(&yaml(K, "-0.1, 0.01, 0., 0., 0., 0.", "")).unwrap_err().0;
        assert!(e.contains("4, 5, 8, 12 or 14"), "{e}");
        // A key inside a comment is not the key; a key given twice is refused.
        let commented = yaml(K, "0., 0., 0., 0., 0.", "# image_width: 9999\n");
        assert_eq!(from_yaml(&commented).unwrap().image_width, 640);
        let e = from_yaml(&yaml(K, "0., 0., 0., 0., 0.", "image_width: 800\n")).unwrap_err().0;
        assert!(e.contains("`image_width` is given twice"), "{e}");
        let e =
            from_yaml(&yaml(K, "0., 0., 0., 0., 0.", "").replace("image_height: 480", "image_height: 1e12"))
                .unwrap_err()
                .0;
        assert!(e.contains("image_height: 1000000000000") && e.contains("whole number"), "{e}");
        // The data list may run over several lines, as OpenCV wraps long ones.
        let wrapped =
            yaml(K, "0., 0., 0., 0., 0.", "").replace("500., 0., 320., 0.,", "500., 0., 320., 0.,\n      ");
        assert!(from_yaml(&wrapped).is_ok());
    }

    /// Skew and a camera matrix whose last rows are not [0, fy, cy], [0, 0, 1] are refused
    /// on reading, in YAML and JSON alike.
    #[test]
    fn a_camera_matrix_lumen_cannot_represent_is_refused() {
        let dir = std::env::temp_dir().join(format!("lumen-calfile-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let skew = dir.join("skew.yaml");
        std::fs::write(&skew, yaml("500., 2., 320., 0., 500., 240., 0., 0., 1.", "0., 0., 0., 0., 0.", ""))
            .unwrap();
        let e = read(&skew).unwrap_err().to_string();
        assert!(e.contains("skew.yaml") && e.contains("skew of 2"), "{e}");
        let mut c = read_yaml_ok();
        c.camera_matrix[2] = [0.0, 0.0, 2.0];
        c.rms_px = 0.5;
        let json = dir.join("bottom.json");
        std::fs::write(&json, serde_json::to_string(&c).unwrap()).unwrap();
        let e = read(&json).unwrap_err().to_string();
        assert!(e.contains("rows 2 and 3") && e.contains("[0.0, 0.0, 2.0]"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    fn read_yaml_ok() -> Calibration {
        from_yaml(&yaml(K, "0., 0., 0., 0., 0.", "")).unwrap()
    }
}
