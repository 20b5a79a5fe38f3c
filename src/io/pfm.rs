//! Portable float map (PFM), Middlebury convention.
//!
//! Header `Pf\n<width> <height>\n<scale>\n` (`PF` = 3 channels), then float32 samples, **rows bottom-to-top**.
//! A negative scale means little-endian, a positive one big-endian. `+inf` marks unknown/invalid disparities and
//! is kept as is. We write greyscale, little-endian, scale −1. Readers accept both byte orders and both channel
//! counts (taking the first channel of `PF`) and `\r\n` line ends, and reject malformed headers and a body that
//! is not exactly width × height × channels floats, without allocating more than the file holds.

use std::path::Path;

use crate::error::{Error, Result};
use crate::image::Plane;

/// Encodes a plane as a greyscale little-endian PFM.
pub fn encode_pfm(map: &Plane<f32>) -> Vec<u8> {
    let header = format!("Pf\n{} {}\n-1\n", map.width, map.height);
    let mut out = Vec::with_capacity(header.len() + map.data.len() * 4);
    out.extend_from_slice(header.as_bytes());
    for y in (0..map.height).rev() {
        for v in map.row(y) {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

/// Decodes a PFM from memory.
///
/// # Errors
/// [`Error::Pfm`] (with an empty path) describing the first problem found.
pub fn decode_pfm(bytes: &[u8]) -> Result<Plane<f32>> {
    decode(bytes).map_err(|msg| Error::Pfm { path: Default::default(), msg })
}

/// Writes a greyscale little-endian PFM atomically.
///
/// # Errors
/// [`Error::Io`] naming the path.
pub fn write_pfm(path: &Path, map: &Plane<f32>) -> Result<()> {
    super::write_atomic(path, &encode_pfm(map))
}

/// Reads a PFM file.
///
/// # Errors
/// [`Error::Io`] if it cannot be read, [`Error::Pfm`] naming the path if it is malformed.
pub fn read_pfm(path: &Path) -> Result<Plane<f32>> {
    use std::io::Read;
    let pfm_error = |msg| Error::Pfm { path: path.to_path_buf(), msg };
    // The header first (three short lines), then exactly the body it announces plus one byte to detect more:
    // a device or a huge file is never read whole.
    let mut file = super::open_regular(path)?;
    let mut bytes = Vec::new();
    file.by_ref().take(3 * (MAX_LINE as u64 + 2)).read_to_end(&mut bytes).map_err(|e| Error::io(path, e))?;
    let (width, height, channels, _, body_start) = header(&bytes).map_err(pfm_error)?;
    let needed = (width * height * channels * 4) as u64;
    let have = (bytes.len() - body_start) as u64;
    file.take((needed + 1).saturating_sub(have)).read_to_end(&mut bytes).map_err(|e| Error::io(path, e))?;
    decode(&bytes).map_err(pfm_error)
}

/// [`read_pfm`] within a memory limit: the size the header announces is checked first (the file's body and the map
/// made of it, 8 bytes a value), so that a header announcing more than `max_bytes` is refused before the body is
/// read.
///
/// # Errors
/// As [`read_pfm`]; [`Error::OutOfMemory`] naming the file when the map does not fit.
pub fn read_pfm_within(path: &Path, max_bytes: u64) -> Result<Plane<f32>> {
    use std::io::Read;
    let file = super::open_regular(path)?;
    let mut bytes = Vec::new();
    file.take(3 * (MAX_LINE as u64 + 2)).read_to_end(&mut bytes).map_err(|e| Error::io(path, e))?;
    let (width, height, channels, ..) = header(&bytes).map_err(|msg| Error::Pfm { path: path.to_path_buf(), msg })?;
    let need = (width as u64).saturating_mul(height as u64).saturating_mul(channels as u64).saturating_mul(8);
    if need > max_bytes {
        return Err(Error::OutOfMemory {
            needed: need,
            limit: max_bytes,
            hint: format!("{}: its {width}x{height} map does not fit; raise the memory limit", path.display()),
        });
    }
    read_pfm(path)
}

/// A PFM file's width and height, from its header (the body is not read).
///
/// # Errors
/// [`Error::Io`] if it cannot be read, [`Error::Pfm`] naming the path if the header is malformed.
#[cfg(feature = "toolkit")]
pub(crate) fn read_pfm_size(path: &Path) -> Result<(usize, usize)> {
    use std::io::Read;
    let file = super::open_regular(path)?;
    let mut bytes = Vec::new();
    file.take(3 * (MAX_LINE as u64 + 2)).read_to_end(&mut bytes).map_err(|e| Error::io(path, e))?;
    let (width, height, ..) = header(&bytes).map_err(|msg| Error::Pfm { path: path.to_path_buf(), msg })?;
    Ok((width, height))
}

/// The longest header line accepted (a width, a space and a height fit in 41 bytes).
const MAX_LINE: usize = 64;

/// The next header line, without its ending: `\n`, or `\r\n` (written by some Windows tools).
fn line<'a>(bytes: &'a [u8], pos: &mut usize, what: &str) -> std::result::Result<&'a str, String> {
    let rest = &bytes[*pos..];
    let end = rest
        .iter()
        .take(MAX_LINE + 2)
        .position(|&b| b == b'\n')
        .ok_or_else(|| format!("the {what} line is not ended by a newline within {MAX_LINE} bytes"))?;
    let text = rest[..end].strip_suffix(b"\r").unwrap_or(&rest[..end]);
    *pos += end + 1;
    std::str::from_utf8(text).map(|t| t.trim_matches(' ')).map_err(|_| format!("the {what} line is not text"))
}

/// Parses the three header lines exactly (`Pf`/`PF`; width and height; scale) and requires the body to hold
/// exactly width × height × channels floats: a misread header shows up as a wrong body length, not as garbage.
fn decode(bytes: &[u8]) -> std::result::Result<Plane<f32>, String> {
    let (width, height, channels, little_endian, pos) = header(bytes)?;
    let data = &bytes[pos..];
    let needed = width * height * channels * 4;
    if data.len() != needed {
        return Err(format!("{width}x{height}x{channels} needs {needed} data bytes but the file has {}", data.len()));
    }
    let mut out = Plane::new(width, height, 0.0f32);
    for (file_row, chunk) in data.chunks_exact(width * channels * 4).enumerate() {
        let y = height - 1 - file_row;
        for (dst, px) in out.row_mut(y).iter_mut().zip(chunk.chunks_exact(channels * 4)) {
            let b = [px[0], px[1], px[2], px[3]];
            *dst = if little_endian { f32::from_le_bytes(b) } else { f32::from_be_bytes(b) };
        }
    }
    Ok(out)
}

/// The header's (width, height, channels, little-endian, where the body starts); width × height × channels × 4
/// fits a usize.
fn header(bytes: &[u8]) -> std::result::Result<(usize, usize, usize, bool, usize), String> {
    let mut pos = 0;
    let magic = line(bytes, &mut pos, "magic").map_err(|_| {
        let start = String::from_utf8_lossy(&bytes[..bytes.len().min(8)]).into_owned();
        format!("bad magic: the file starts {start:?} (expected a line \"Pf\" or \"PF\")")
    })?;
    let channels = match magic {
        "Pf" => 1,
        "PF" => 3,
        other => return Err(format!("bad magic {other:?} (expected \"Pf\" or \"PF\" on its own line)")),
    };
    let dim = |s: &str, what: &str| -> std::result::Result<usize, String> {
        match s.parse::<usize>() {
            Ok(v) if v > 0 => Ok(v),
            _ => Err(format!("bad {what} {s:?} (expected a positive integer)")),
        }
    };
    let dims = line(bytes, &mut pos, "size")?;
    let fields: Vec<&str> = dims.split_ascii_whitespace().collect();
    let [w, h] = fields[..] else {
        return Err(format!("bad size line {dims:?} (expected \"<width> <height>\")"));
    };
    let (width, height) = (dim(w, "width")?, dim(h, "height")?);
    let scale_text = line(bytes, &mut pos, "scale")?;
    let scale: f32 = scale_text.parse().map_err(|_| format!("bad scale {scale_text:?}"))?;
    if scale == 0.0 || !scale.is_finite() {
        return Err(format!("bad scale {scale_text:?} (expected a non-zero number)"));
    }
    width
        .checked_mul(height)
        .and_then(|n| n.checked_mul(channels))
        .and_then(|n| n.checked_mul(4))
        .ok_or_else(|| format!("size {width}x{height} overflows"))?;
    Ok((width, height, channels, scale < 0.0, pos))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Plane<f32> {
        Plane::from_parts(3, 2, vec![0.0, 1.5, f32::INFINITY, -2.0, 1e-3, 1e6])
    }

    #[test]
    fn round_trip_keeps_values_and_inf() {
        let p = sample();
        let back = decode_pfm(&encode_pfm(&p)).unwrap();
        assert_eq!(back, p);
    }

    #[test]
    fn rows_are_stored_bottom_to_top() {
        let bytes = encode_pfm(&sample());
        let header = b"Pf\n3 2\n-1\n";
        assert_eq!(&bytes[..header.len()], header);
        let first = f32::from_le_bytes(bytes[header.len()..][..4].try_into().unwrap());
        assert_eq!(first, -2.0, "the first stored row is the image's bottom row");
    }

    #[test]
    fn reads_big_endian_and_colour() {
        let mut bytes = b"PF\n1 2\n1.0\n".to_vec();
        for v in [7.0f32, 0.0, 0.0, 8.0, 0.0, 0.0] {
            bytes.extend_from_slice(&v.to_be_bytes());
        }
        let p = decode_pfm(&bytes).unwrap();
        assert_eq!(p.data, vec![8.0, 7.0]);
    }

    #[test]
    fn rejects_malformed_headers() {
        let body = [0u8; 64];
        for header in [
            &b"P5\n1 1\n-1\n"[..],
            b"Pf\n0 1\n-1\n",
            b"Pf\n-1 1\n-1\n",
            b"Pf\nx 1\n-1\n",
            b"Pf\n1 1\n0\n",
            b"Pf\n1 1\nnan\n",
            b"Pf\n1 1\n",
            b"Pf\n1",
            b"",
            b"Pf\n99999999999999999999 1\n-1\n",
            b"Pf\n4294967296 4294967296\n-1\n",
        ] {
            let mut bytes = header.to_vec();
            bytes.extend_from_slice(&body);
            assert!(decode_pfm(&bytes).is_err(), "accepted {:?}", String::from_utf8_lossy(header));
        }
    }

    #[test]
    fn rejects_truncated_data() {
        let bytes = encode_pfm(&sample());
        for cut in [bytes.len() - 1, bytes.len() - 4, 12] {
            let e = decode_pfm(&bytes[..cut]).unwrap_err();
            assert!(e.to_string().contains("needs 24 data bytes"), "{e}");
        }
    }

    /// A header with CRLF line ends is read correctly; a body with bytes left over is an error (
    /// both were read as garbage before).
    #[test]
    fn crlf_headers_and_exact_body_length() {
        let good = encode_pfm(&sample());
        let body = &good[b"Pf\n3 2\n-1\n".len()..];
        let mut crlf = b"Pf\r\n3 2\r\n-1\r\n".to_vec();
        crlf.extend_from_slice(body);
        assert_eq!(decode_pfm(&crlf).unwrap(), sample());
        let mut long = good.clone();
        long.push(0);
        let e = decode_pfm(&long).unwrap_err().to_string();
        assert!(e.contains("needs 24 data bytes but the file has 25"), "{e}");
        // Fields on the wrong lines.
        for header in [&b"Pf 3 2 -1\n"[..], b"Pf\n3\n2\n-1\n", b"Pf\n3 2 -1\n"] {
            let mut bytes = header.to_vec();
            bytes.extend_from_slice(body);
            assert!(decode_pfm(&bytes).is_err(), "accepted {:?}", String::from_utf8_lossy(header));
        }
    }

    #[test]
    fn file_round_trip_names_path_on_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.pfm");
        write_pfm(&p, &sample()).unwrap();
        assert_eq!(read_pfm(&p).unwrap(), sample());
        std::fs::write(&p, b"garbage").unwrap();
        let e = read_pfm(&p).unwrap_err().to_string();
        assert!(e.contains("d.pfm") && e.contains("bad magic"), "{e}");
    }
}
