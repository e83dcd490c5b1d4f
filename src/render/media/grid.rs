//! Voxel grids of density, read from Mitsuba's binary `.vol` files and looked up trilinearly.
//!
//! The format (Mitsuba's `gridvolume`, little-endian): the bytes `VOL` and version 3; an
//! int32 encoding, 1 for float32; int32 sizes x, y, z; int32 channels (1 or 3); six float32,
//! the box the grid spans (x, y, z min, then max); then x·y·z·channels float32 values, x
//! fastest, channels innermost. Values sit at the centres of the cells dividing [0, 1]³ (the
//! grid's own coordinates), interpolated trilinearly, clamped to the outer centres at the
//! edge, and are 0 outside the cube (as Mitsuba's, with its default linear filter and clamp).
//! A header whose sizes do not match the file's length, or ask for more than `MAX_VOXELS`, is
//! refused before anything is allocated.

use glam::Vec3A;
use std::path::{Path, PathBuf};

/// The most values a grid may hold (2²⁸ float32, 1 GiB).
pub const MAX_VOXELS: u64 = 1 << 28;

const HEADER: u64 = 48;

#[derive(Debug, thiserror::Error)]
pub enum GridError {
    #[error("cannot read {path}: {message}")]
    Io { path: PathBuf, message: String },
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
}

impl GridError {
    pub fn fault(&self) -> crate::Fault {
        match self {
            GridError::Io { .. } => crate::Fault::Io,
            GridError::Format { .. } => crate::Fault::BadInput,
        }
    }
}

/// Voxels per side of a brick, the unit over which a grid's majorant is kept
/// (`brick_maxima`, `media::Density`).
pub const BRICK: usize = 8;

/// A voxel grid over [0, 1]³.
#[derive(Clone, Debug)]
pub struct Grid {
    pub size: [usize; 3],
    /// 1 or 3.
    pub channels: usize,
    /// The box the file says the grid spans (min, max), for `use_grid_bbox`.
    pub bbox: (Vec3A, Vec3A),
    data: Vec<f32>,
    /// The largest value of any voxel and channel.
    pub max: f32,
}

impl Grid {
    /// A grid over [0, 1]³ from its values (x fastest, then y, then z; `channels` per voxel),
    /// as a procedural density makes one (`media::noise`). Values must be finite and ≥ 0.
    pub fn from_values(size: [usize; 3], channels: usize, data: Vec<f32>) -> Grid {
        debug_assert_eq!(data.len(), size[0] * size[1] * size[2] * channels);
        let max = data.iter().copied().fold(0.0f32, f32::max);
        Grid { size, channels, bbox: (Vec3A::ZERO, Vec3A::ONE), data, max }
    }

    /// Reads a `.vol` file, checking its header against its length and its values (finite,
    /// ≥ 0: a grid holds densities).
    pub fn read(path: &Path) -> Result<Grid, GridError> {
        let io = |e: std::io::Error| GridError::Io { path: path.to_path_buf(), message: e.to_string() };
        let bad = |m: String| GridError::Format { path: path.to_path_buf(), message: m };
        let len = std::fs::metadata(path).map_err(io)?.len();
        if len < HEADER {
            return Err(bad(format!("{len} bytes is shorter than a .vol header ({HEADER} bytes)")));
        }
        use std::io::Read;
        let mut f = std::fs::File::open(path).map_err(io)?;
        let mut h = [0u8; HEADER as usize];
        f.read_exact(&mut h).map_err(io)?;
        if &h[0..3] != b"VOL" || h[3] != 3 {
            return Err(bad("not a Mitsuba .vol file (expected the bytes VOL and version 3)".into()));
        }
        let int = |i: usize| i32::from_le_bytes([h[i], h[i + 1], h[i + 2], h[i + 3]]);
        let float = |i: usize| f32::from_le_bytes([h[i], h[i + 1], h[i + 2], h[i + 3]]);
        if int(4) != 1 {
            return Err(bad(format!("encoding {}: lumen reads float32 grids (encoding 1)", int(4))));
        }
        let (nx, ny, nz, channels) = (int(8), int(12), int(16), int(20));
        if nx < 1 || ny < 1 || nz < 1 {
            return Err(bad(format!("sizes {nx} × {ny} × {nz}: each must be at least 1")));
        }
        if channels != 1 && channels != 3 {
            return Err(bad(format!("{channels} channels: lumen reads grids of 1 or 3")));
        }
        let values = nx as u64 * ny as u64 * nz as u64 * channels as u64;
        if values > MAX_VOXELS {
            return Err(bad(format!(
                "{nx} × {ny} × {nz} × {channels} values is more than lumen reads ({MAX_VOXELS})"
            )));
        }
        if len != HEADER + 4 * values {
            return Err(bad(format!(
                "the header says {nx} × {ny} × {nz} × {channels} float32 values ({} bytes with the header), the file has {len} bytes",
                HEADER + 4 * values
            )));
        }
        let lo = Vec3A::new(float(24), float(28), float(32));
        let hi = Vec3A::new(float(36), float(40), float(44));
        let mut bytes = vec![0u8; 4 * values as usize];
        f.read_exact(&mut bytes).map_err(io)?;
        let data: Vec<f32> =
            bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        if let Some(i) = data.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(bad(format!("value {i} is {}: a density must be finite and ≥ 0", data[i])));
        }
        let max = data.iter().fold(0.0f32, |m, &v| m.max(v));
        Ok(Grid {
            size: [nx as usize, ny as usize, nz as usize],
            channels: channels as usize,
            bbox: (lo, hi),
            data,
            max,
        })
    }

    /// The largest value (any channel) the trilinear lookup can return inside each brick of
    /// `BRICK`³ voxels: bricks indexed x fastest, `ceil(size / BRICK)` per axis. A brick's
    /// lookups read the voxels from one before it to one after it on each axis.
    pub fn brick_maxima(&self) -> ([usize; 3], Vec<f32>) {
        let res = self.size.map(|n| n.div_ceil(BRICK));
        let mut out = vec![0.0f32; res[0] * res[1] * res[2]];
        for bz in 0..res[2] {
            for by in 0..res[1] {
                for bx in 0..res[0] {
                    let b = [bx, by, bz];
                    let range = |a: usize| {
                        let lo = (b[a] * BRICK).saturating_sub(1);
                        let hi = ((b[a] + 1) * BRICK).min(self.size[a] - 1);
                        lo..=hi
                    };
                    let mut m = 0.0f32;
                    for z in range(2) {
                        for y in range(1) {
                            let row = (z * self.size[1] + y) * self.size[0];
                            for x in range(0) {
                                let k = (row + x) * self.channels;
                                for c in 0..self.channels {
                                    m = m.max(self.data[k + c]);
                                }
                            }
                        }
                    }
                    out[(bz * res[1] + by) * res[0] + bx] = m;
                }
            }
        }
        (res, out)
    }

    /// The trilinear value at `p` in the grid's coordinates ([0, 1]³), every channel (a
    /// one-channel grid's value in all three); 0 outside the cube.
    pub fn eval(&self, p: Vec3A) -> Vec3A {
        if !(p.cmpge(Vec3A::ZERO).all() && p.cmple(Vec3A::ONE).all()) {
            return Vec3A::ZERO;
        }
        let mut i0 = [0usize; 3];
        let mut i1 = [0usize; 3];
        let mut f = [0.0f32; 3];
        for a in 0..3 {
            let n = self.size[a];
            let x = (p[a] * n as f32 - 0.5).clamp(0.0, (n - 1) as f32);
            let lo = (x as usize).min(n - 1);
            i0[a] = lo;
            i1[a] = (lo + 1).min(n - 1);
            f[a] = x - lo as f32;
        }
        let at = |x: usize, y: usize, z: usize| -> Vec3A {
            let k = ((z * self.size[1] + y) * self.size[0] + x) * self.channels;
            if self.channels == 1 {
                Vec3A::splat(self.data[k])
            } else {
                Vec3A::new(self.data[k], self.data[k + 1], self.data[k + 2])
            }
        };
        let lerp = |a: Vec3A, b: Vec3A, t: f32| a + (b - a) * t;
        let c00 = lerp(at(i0[0], i0[1], i0[2]), at(i1[0], i0[1], i0[2]), f[0]);
        let c10 = lerp(at(i0[0], i1[1], i0[2]), at(i1[0], i1[1], i0[2]), f[0]);
        let c01 = lerp(at(i0[0], i0[1], i1[2]), at(i1[0], i0[1], i1[2]), f[0]);
        let c11 = lerp(at(i0[0], i1[1], i1[2]), at(i1[0], i1[1], i1[2]), f[0]);
        lerp(lerp(c00, c10, f[1]), lerp(c01, c11, f[1]), f[2])
    }
}

/// Writes a `.vol` file (for tests and tools): sizes, channels, box and values as `Grid::read`
/// reads them.
pub fn write(
    path: &Path,
    size: [u32; 3],
    channels: u32,
    bbox: ([f32; 3], [f32; 3]),
    values: &[f32],
) -> std::io::Result<()> {
    let mut out = Vec::with_capacity(HEADER as usize + 4 * values.len());
    out.extend_from_slice(b"VOL\x03");
    for v in [1, size[0] as i32, size[1] as i32, size[2] as i32, channels as i32] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for v in bbox.0.iter().chain(&bbox.1).chain(values) {
        out.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(path, out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_trilinear_lookup() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("g.vol");
        // 2 × 1 × 1, values 1 and 3: the centres at x = 0.25 and 0.75.
        write(&p, [2, 1, 1], 1, ([0.0; 3], [1.0; 3]), &[1.0, 3.0]).unwrap();
        let g = Grid::read(&p).unwrap();
        assert_eq!((g.size, g.channels, g.max), ([2, 1, 1], 1, 3.0));
        let at = |x: f32| g.eval(Vec3A::new(x, 0.5, 0.5)).x;
        assert_eq!(at(0.1), 1.0, "clamped to the first centre");
        assert_eq!(at(0.5), 2.0);
        assert_eq!(at(0.9), 3.0);
        assert_eq!(g.eval(Vec3A::new(1.01, 0.5, 0.5)), Vec3A::ZERO, "0 outside the cube");
    }

    #[test]
    fn lying_headers_are_refused_before_allocating() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("g.vol");
        write(&p, [4, 4, 4], 1, ([0.0; 3], [1.0; 3]), &[0.5; 60]).unwrap();
        let e = Grid::read(&p).unwrap_err().to_string();
        assert!(e.contains("4 × 4 × 4 × 1") && e.contains("the file has"), "{e}");
        write(&p, [1000, 1000, 1000], 1, ([0.0; 3], [1.0; 3]), &[0.5; 8]).unwrap();
        let e = Grid::read(&p).unwrap_err().to_string();
        assert!(e.contains("more than lumen reads"), "{e}");
        std::fs::write(&p, b"VOL\x03\x01\x00").unwrap();
        let e = Grid::read(&p).unwrap_err().to_string();
        assert!(e.contains("shorter than a .vol header"), "{e}");
        write(&p, [1, 1, 1], 1, ([0.0; 3], [1.0; 3]), &[-1.0]).unwrap();
        let e = Grid::read(&p).unwrap_err().to_string();
        assert!(e.contains("finite and ≥ 0"), "{e}");
        write(&p, [1, 1, 1], 2, ([0.0; 3], [1.0; 3]), &[1.0, 1.0]).unwrap();
        let e = Grid::read(&p).unwrap_err().to_string();
        assert!(e.contains("2 channels"), "{e}");
    }
}
