//! Reading a photometric-stereo dataset in DiLiGenT's layout (Shi et al. 2016/2019):
//! `filenames.txt` (the images, in order; 16-bit PNGs read at full depth, their largest codes
//! flagged as saturated; EXRs as linear values, never clipped),
//! `light_directions.txt` (one unit vector per image, from the object towards the light),
//! `light_intensities.txt` (per-channel intensity per image), `mask.png` (any non-zero channel
//! marks the object) and, optionally, `Normal_gt.mat` (MATLAB v5, variable `Normal_gt`,
//! height × width × 3). Directions and normals stay in the dataset's frame (x right, y up,
//! z towards the camera): the solvers only need lights and normals in one frame.

use super::{Error, Input, Observations};
use glam::DVec3;
use rayon::prelude::*;
use std::path::Path;

/// A dataset read into memory, reduced to the pixels inside the mask: what the solver reads,
/// and the ground truth beside it (never inside it).
pub struct Dataset {
    pub input: Input,
    /// Ground-truth unit normals of the masked pixels, when the dataset has them.
    pub truth: Option<Vec<DVec3>>,
}

fn bad(path: &Path, message: impl Into<String>) -> Error {
    Error::BadInput { path: path.to_path_buf(), message: message.into() }
}

fn unreadable(path: &Path, e: std::io::Error) -> Error {
    Error::Read { path: path.to_path_buf(), message: e.to_string() }
}

/// Writes `input` (and `truth`, as `Normal_gt.mat`) in the layout `read` reads, into `dir`
/// as (file name, bytes) pairs: `images` are the raw per-light images (linear, EXR) whose
/// masked pixels, divided by the intensities, are `input`'s observations. Light directions are
/// written with every digit, so reading the files back gives the same numbers.
pub fn layout(
    input: &Input,
    images: Vec<(String, crate::image::Image)>,
    truth: Option<&[DVec3]>,
) -> (Vec<(String, crate::image::Image)>, Vec<(String, Vec<u8>)>) {
    let mut files = Vec::new();
    let names: Vec<&str> = images.iter().map(|(n, _)| n.as_str()).collect();
    files.push(("filenames.txt".to_string(), (names.join("\n") + "\n").into_bytes()));
    let rows = |v: Vec<[f64; 3]>| -> Vec<u8> {
        v.iter().map(|r| format!("{:?} {:?} {:?}\n", r[0], r[1], r[2])).collect::<String>().into_bytes()
    };
    files.push(("light_directions.txt".into(), rows(input.lights.iter().map(|l| l.to_array()).collect())));
    files.push(("light_intensities.txt".into(), rows(input.intensities.clone())));
    let (w, h) = (input.width, input.height);
    if let Some(truth) = truth {
        // Column-major height × width × 3, zero outside the mask.
        let mut values = vec![0.0; w * h * 3];
        for (&i, n) in input.pixels.iter().zip(truth) {
            for k in 0..3 {
                values[i / w + h * (i % w + w * k)] = n[k];
            }
        }
        files.push(("Normal_gt.mat".into(), super::mat::write_variable("Normal_gt", &[h, w, 3], &values)));
    }
    let mut mask = crate::image::Image::new(w as u32, h as u32, 1);
    for &i in &input.pixels {
        mask.data[i] = 1.0;
    }
    let mut out_images = images;
    out_images.push(("mask.png".into(), mask));
    (out_images, files)
}

/// Rows of whitespace-separated numbers, each with exactly `cols` values.
fn table(path: &Path, cols: usize) -> Result<Vec<Vec<f64>>, Error> {
    let text = std::fs::read_to_string(path).map_err(|e| unreadable(path, e))?;
    let mut rows = Vec::new();
    for (k, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let row: Vec<f64> = line
            .split_whitespace()
            .map(|t| t.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect::<Option<_>>()
            .ok_or_else(|| bad(path, format!("line {}: `{line}` is not {cols} numbers", k + 1)))?;
        if row.len() != cols {
            return Err(bad(path, format!("line {}: {} values, expected {cols}", k + 1, row.len())));
        }
        rows.push(row);
    }
    Ok(rows)
}

/// Reads the dataset in `dir`.
pub fn read(dir: &Path) -> Result<Dataset, Error> {
    let list = dir.join("filenames.txt");
    let names: Vec<String> = std::fs::read_to_string(&list)
        .map_err(|e| unreadable(&list, e))?
        .lines()
        .map(|l| l.trim().to_string())
        .filter(|l| !l.is_empty())
        .collect();
    let dirs_path = dir.join("light_directions.txt");
    let ints_path = dir.join("light_intensities.txt");
    let dirs = table(&dirs_path, 3)?;
    let ints = table(&ints_path, 3)?;
    for (path, n) in [(&dirs_path, dirs.len()), (&ints_path, ints.len())] {
        if n != names.len() {
            return Err(bad(path, format!("{n} rows, but filenames.txt lists {} images", names.len())));
        }
    }
    let mut lights = Vec::new();
    for (k, d) in dirs.iter().enumerate() {
        let v = DVec3::new(d[0], d[1], d[2]);
        if (v.length() - 1.0).abs() > 0.01 {
            return Err(bad(
                &dirs_path,
                format!("line {}: length {:.4}, expected a unit vector", k + 1, v.length()),
            ));
        }
        lights.push(v.normalize());
    }
    let mut intensities = Vec::new();
    for (k, e) in ints.iter().enumerate() {
        if e.iter().any(|&v| v <= 0.0) {
            return Err(bad(&ints_path, format!("line {}: intensities must be positive", k + 1)));
        }
        intensities.push([e[0], e[1], e[2]]);
    }

    let mask_path = dir.join("mask.png");
    let mask_img = crate::image::io::read_raw(&mask_path)?;
    let (width, height) = (mask_img.width as usize, mask_img.height as usize);
    let mc = mask_img.channels as usize;
    let pixels: Vec<usize> = (0..width * height)
        .filter(|&i| mask_img.data[i * mc..(i + 1) * mc].iter().any(|&v| v > 0.0))
        .collect();

    // Images in parallel, each reduced at once to the masked pixels.
    let per_image: Vec<Vec<[f32; 3]>> = names
        .par_iter()
        .map(|name| {
            let path = dir.join(name);
            let img = crate::image::io::read(&path)?;
            if (img.width as usize, img.height as usize) != (width, height) {
                return Err(bad(
                    &path,
                    format!("{}×{}, but mask.png is {width}×{height}", img.width, img.height),
                ));
            }
            let c = img.channels as usize;
            Ok(pixels
                .iter()
                .map(|&i| {
                    let p = &img.data[i * c..(i + 1) * c];
                    std::array::from_fn(|ch| p[ch.min(c - 1)])
                })
                .collect())
        })
        .collect::<Result<_, Error>>()?;
    let mut obs = Observations::new(pixels.len(), names.len());
    for (j, img) in per_image.iter().enumerate() {
        // Code values (PNG, JPEG) saturate at the largest code; linear float images (EXR) are
        // not clipped at 1.
        let linear = names[j].to_ascii_lowercase().ends_with(".exr");
        for (p, v) in img.iter().enumerate() {
            if linear {
                obs.set_linear(p, j, *v, intensities[j]);
            } else {
                obs.set_raw(p, j, *v, intensities[j]);
            }
        }
    }

    let gt_path = dir.join("Normal_gt.mat");
    let truth = if gt_path.exists() {
        let bytes = std::fs::read(&gt_path).map_err(|e| unreadable(&gt_path, e))?;
        let a = super::mat::read_variable(&bytes, "Normal_gt").map_err(|m| bad(&gt_path, m.0))?;
        if a.dims != [height, width, 3] {
            return Err(bad(
                &gt_path,
                format!("`Normal_gt` is {:?}, expected [{height}, {width}, 3]", a.dims),
            ));
        }
        // Column-major: element (row, col, k) at row + height·(col + width·k).
        let at = |i: usize, k: usize| a.data[i / width + height * (i % width + width * k)];
        Some(pixels.iter().map(|&i| DVec3::new(at(i, 0), at(i, 1), at(i, 2))).collect())
    } else {
        None
    };
    Ok(Dataset { input: Input { width, height, lights, intensities, pixels, obs, views: None }, truth })
}
