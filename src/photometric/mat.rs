//! Reading one numeric array from a MATLAB v5 MAT-file (as DiLiGenT stores its ground-truth
//! normals): the 128-byte header, then tagged data elements, each possibly zlib-compressed
//! (`miCOMPRESSED`, type 15) around a `miMATRIX` (type 14) holding array flags, dimensions,
//! the name and the real part. Only little-endian files and the numeric classes a normal map
//! uses are read; anything else is refused by name. Format: MathWorks, "MAT-File Format",
//! version 5 (2021 edition), chapter 1.

use crate::error::Invalid;
use std::io::Read;

const MI_INT8: u32 = 1;
const MI_UINT8: u32 = 2;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_SINGLE: u32 = 7;
const MI_DOUBLE: u32 = 9;
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;

/// Largest inflated element read: the image readers' decoded-size limit (a 16384² normal map
/// in f64 is 6 GB and far beyond what the solvers accept anyway).
pub const MAX_INFLATED_BYTES: u64 = crate::image::io::MAX_DECODED_BYTES;

/// A numeric array: its dimensions and its values in MATLAB's column-major order.
#[derive(Debug)]
pub struct Array {
    pub dims: Vec<usize>,
    pub data: Vec<f64>,
}

/// One data element: (type, payload, bytes consumed including padding to 8).
fn element(bytes: &[u8]) -> Result<(u32, &[u8], usize), Invalid> {
    if bytes.len() < 8 {
        return Err("truncated data element tag".into());
    }
    let word = u32::from_le_bytes(bytes[0..4].try_into().unwrap_or_default());
    if word >> 16 != 0 {
        // Small element: type and size in one word, up to 4 bytes of data in the next.
        let (ty, size) = (word & 0xffff, (word >> 16) as usize);
        if size > 4 {
            return Err(format!("small data element of {size} bytes").into());
        }
        return Ok((ty, &bytes[4..4 + size], 8));
    }
    let size = u32::from_le_bytes(bytes[4..8].try_into().unwrap_or_default()) as usize;
    if bytes.len() < 8 + size {
        return Err(format!("data element of {size} bytes runs past the end").into());
    }
    let padded = if word == MI_COMPRESSED { size } else { size.div_ceil(8) * 8 };
    Ok((word, &bytes[8..8 + size], (8 + padded).min(bytes.len())))
}

fn numbers(ty: u32, data: &[u8]) -> Result<Vec<f64>, Invalid> {
    fn each<const N: usize>(data: &[u8], f: impl Fn([u8; N]) -> f64) -> Vec<f64> {
        data.chunks_exact(N).map(|c| f(c.try_into().unwrap_or([0; N]))).collect()
    }
    Ok(match ty {
        MI_DOUBLE => each::<8>(data, f64::from_le_bytes),
        MI_SINGLE => each::<4>(data, |b| f32::from_le_bytes(b) as f64),
        MI_INT32 => each::<4>(data, |b| i32::from_le_bytes(b) as f64),
        MI_UINT32 => each::<4>(data, |b| u32::from_le_bytes(b) as f64),
        MI_UINT8 => data.iter().map(|&v| v as f64).collect(),
        MI_INT8 => data.iter().map(|&v| v as i8 as f64).collect(),
        other => return Err(format!("numeric data of MAT type {other} is not supported").into()),
    })
}

/// Parses a `miMATRIX` payload; returns its name and array.
fn matrix(payload: &[u8]) -> Result<(String, Array), Invalid> {
    let mut at = 0;
    let mut next = || -> Result<(u32, &[u8]), Invalid> {
        let (ty, data, used) = element(&payload[at.min(payload.len())..])?;
        at += used;
        Ok((ty, data))
    };
    let (_, flags) = next()?;
    let class = flags.first().copied().unwrap_or(0);
    let complex = flags.get(1).is_some_and(|f| f & 0x08 != 0);
    // Classes 6–13 are double, single and the integer types.
    if !(6..=13).contains(&class) || complex {
        return Err(format!(
            "array class {class}{} is not a real numeric array",
            if complex { " (complex)" } else { "" }
        )
        .into());
    }
    let (ty, dims) = next()?;
    let dims: Vec<usize> = numbers(ty, dims)?.into_iter().map(|d| d as usize).collect();
    let (_, name) = next()?;
    let name = String::from_utf8_lossy(name).into_owned();
    let (ty, real) = next()?;
    let data = numbers(ty, real)?;
    if data.len() != dims.iter().product::<usize>() {
        return Err(format!("`{name}`: {} values for dimensions {dims:?}", data.len()).into());
    }
    Ok((name, Array { dims, data }))
}

/// The variable `name` from the MAT-file bytes.
pub fn read_variable(bytes: &[u8], name: &str) -> Result<Array, Invalid> {
    if bytes.len() < 128 || !bytes.starts_with(b"MATLAB 5.0 MAT-file") {
        return Err("not a MATLAB 5.0 MAT-file".into());
    }
    if &bytes[126..128] != b"IM" {
        return Err("a big-endian MAT-file (only little-endian files are read)".into());
    }
    let mut at = 128;
    let mut seen = Vec::new();
    while at < bytes.len() {
        let (ty, payload, used) = element(&bytes[at..])?;
        at += used;
        let inflated;
        let (ty, payload) = if ty == MI_COMPRESSED {
            // Inflated with a limit: a small file may claim gigabytes (a zip bomb).
            let mut out = Vec::new();
            flate2::read::ZlibDecoder::new(payload)
                .take(MAX_INFLATED_BYTES + 1)
                .read_to_end(&mut out)
                .map_err(|e| format!("compressed element: {e}"))?;
            if out.len() as u64 > MAX_INFLATED_BYTES {
                return Err(format!(
                    "a compressed element inflates to more than {} MB, the limit for a normal map",
                    MAX_INFLATED_BYTES >> 20
                )
                .into());
            }
            inflated = out;
            let (t, p, _) = element(&inflated)?;
            (t, p)
        } else {
            (ty, payload)
        };
        if ty != MI_MATRIX {
            continue;
        }
        let (n, array) = matrix(payload)?;
        if n == name {
            return Ok(array);
        }
        seen.push(n);
    }
    Err(format!("no variable `{name}` (the file holds {seen:?})").into())
}

/// One data element: tag, payload, zero padding to 8 bytes.
fn tag(ty: u32, data: &[u8]) -> Vec<u8> {
    let mut v = ty.to_le_bytes().to_vec();
    v.extend((data.len() as u32).to_le_bytes());
    v.extend(data);
    while v.len() % 8 != 0 {
        v.push(0);
    }
    v
}

/// An uncompressed `miMATRIX` element holding a real double array.
fn matrix_element(name: &str, dims: &[usize], values: &[f64]) -> Vec<u8> {
    let mut p = tag(MI_UINT32, &[6, 0, 0, 0, 0, 0, 0, 0]); // mxDOUBLE_CLASS, no flags
    p.extend(tag(MI_INT32, &dims.iter().flat_map(|&d| (d as i32).to_le_bytes()).collect::<Vec<u8>>()));
    p.extend(tag(MI_INT8, name.as_bytes()));
    p.extend(tag(MI_DOUBLE, &values.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>()));
    tag(MI_MATRIX, &p)
}

/// A little-endian MAT-file holding one double array `name` of dimensions `dims`, its values
/// in MATLAB's column-major order (what `read_variable` reads back).
pub fn write_variable(name: &str, dims: &[usize], values: &[f64]) -> Vec<u8> {
    let mut file = b"MATLAB 5.0 MAT-file, written by lumen".to_vec();
    file.resize(116, b' ');
    file.extend([0u8; 8]); // no subsystem data
    file.extend([0, 1, b'I', b'M']); // version 0x0100, little-endian
    file.extend(matrix_element(name, dims, values));
    file
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-built file: an uncompressed 2×3 double array `A` and a compressed 1×2 `B`.
    #[test]
    fn reads_plain_and_compressed_arrays() {
        let mut file = write_variable("A", &[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        std::io::Write::write_all(&mut z, &matrix_element("B", &[1, 2], &[-0.5, 0.25])).unwrap();
        let packed = z.finish().unwrap();
        file.extend(MI_COMPRESSED.to_le_bytes());
        file.extend((packed.len() as u32).to_le_bytes());
        file.extend(packed);
        let a = read_variable(&file, "A").unwrap();
        assert_eq!((a.dims.clone(), a.data.clone()), (vec![2, 3], vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]));
        let b = read_variable(&file, "B").unwrap();
        assert_eq!(b.data, vec![-0.5, 0.25]);
        let e = read_variable(&file, "C").unwrap_err().0;
        assert!(e.contains("`C`") && e.contains("\"A\""), "{e}");
        assert!(read_variable(b"hello", "A").unwrap_err().0.contains("not a MATLAB"));
        // Truncated: an error, not a panic.
        assert!(read_variable(&file[..file.len() - 10], "B").is_err());
    }

    /// A compressed element that inflates beyond the limit is refused while inflating, not
    /// after allocating it all.
    #[test]
    fn a_compressed_element_inflating_past_the_limit_is_refused() {
        let mut file = write_variable("A", &[1, 1], &[1.0]);
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
        let zeros = vec![0u8; 1 << 20];
        for _ in 0..(MAX_INFLATED_BYTES >> 20) + 1 {
            std::io::Write::write_all(&mut z, &zeros).unwrap();
        }
        let packed = z.finish().unwrap();
        assert!(packed.len() < 4 << 20, "{} bytes packed", packed.len());
        file.extend(MI_COMPRESSED.to_le_bytes());
        file.extend((packed.len() as u32).to_le_bytes());
        file.extend(packed);
        let e = read_variable(&file, "B").unwrap_err().0;
        assert!(e.contains("inflates to more than 512 MB"), "{e}");
    }
}
