//! OpenEXR disparity maps: one 32-bit float channel named `Y`, rows top-to-bottom, inf kept as inf.

use std::io::Cursor;
use std::path::Path;

use exr::prelude::*;

use crate::error::{Error as JemError, Result};
use crate::image::Plane;

/// Encodes a plane as a single-channel float EXR (ZIP-compressed, lossless).
///
/// # Errors
/// [`JemError::Exr`] naming `path` if the encoder fails.
pub(crate) fn encode_exr(path: &Path, map: &Plane<f32>) -> Result<Vec<u8>> {
    let channel = AnyChannel::new("Y", FlatSamples::F32(map.data.clone()));
    let layer = Layer::new(
        (map.width, map.height),
        LayerAttributes::named("disparity"),
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(exr::prelude::SmallVec::from_elem(channel, 1)),
    );
    let mut bytes = Cursor::new(Vec::new());
    // One thread: the parallel encoder stores the compressed blocks in the order they finish, so the same map
    // gave different bytes from run to run (the pixels were equal; the files were not).
    Image::from_layer(layer)
        .write()
        .non_parallel()
        .to_buffered(&mut bytes)
        .map_err(|source| JemError::Exr { path: path.to_path_buf(), source })?;
    Ok(bytes.into_inner())
}

/// Writes a single-channel float EXR atomically.
///
/// # Errors
/// [`JemError::Exr`] or [`JemError::Io`] naming the path.
#[cfg(test)]
pub(crate) fn write_exr(path: &Path, map: &Plane<f32>) -> Result<()> {
    let bytes = encode_exr(path, map)?;
    super::write_atomic(path, &bytes)
}

/// Reads the first float channel (preferring `Y`) of the first layer of an EXR file.
///
/// # Errors
/// [`JemError::Io`] or [`JemError::Exr`] naming the path.
pub(crate) fn read_exr(path: &Path) -> Result<Plane<f32>> {
    let bytes = super::read_regular(path)?;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map_err(|source| JemError::Exr { path: path.to_path_buf(), source })?;
    let layer = &image.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let channels = &layer.channel_data.list;
    let chosen = channels.iter().find(|c| c.name.eq("Y")).or_else(|| channels.first());
    let Some(channel) = chosen else {
        return Err(JemError::bad_image_at(path, "EXR has no channels"));
    };
    let data: Vec<f32> = channel.sample_data.values_as_f32().collect();
    if data.len() != w * h {
        return Err(JemError::bad_image_at(path, "EXR channel has the wrong number of samples"));
    }
    Ok(Plane::from_parts(w, h, data))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_keeps_orientation_and_inf() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.exr");
        let map = Plane::from_parts(3, 2, vec![0.0, 1.5, f32::INFINITY, -2.0, 1e-3, 1e6]);
        write_exr(&p, &map).unwrap();
        assert_eq!(read_exr(&p).unwrap(), map);
    }

    /// The same map gives the same bytes every time (the parallel encoder did not: blocks in finishing order).
    #[test]
    fn encoding_is_deterministic() {
        let data = crate::test_util::rand_vec(640 * 480, 9);
        let map = Plane::from_parts(640, 480, data);
        let first = encode_exr(Path::new("d.exr"), &map).unwrap();
        for _ in 0..4 {
            assert!(encode_exr(Path::new("d.exr"), &map).unwrap() == first, "different bytes for the same map");
        }
    }

    #[test]
    fn garbage_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.exr");
        std::fs::write(&p, b"not an exr file at all").unwrap();
        assert!(read_exr(&p).unwrap_err().to_string().contains("bad.exr"));
    }
}
