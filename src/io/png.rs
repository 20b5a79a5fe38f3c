//! Raster images: loading the formats of [`IMAGE_FORMATS`] into [`RgbImage`], writing 8-bit colour PNGs and 16-bit
//! disparity PNGs.
//!
//! Loading accepts 8- and 16-bit grey, grey+alpha, RGB and RGBA (and TIFF's float samples on the 0..1 scale,
//! through 16 bits; a float sample outside it, which would be clipped, or a NaN is refused);
//! samples are scaled to 0..=255 `f32` (16-bit values divided by 257), alpha is dropped. The format is sniffed
//! from the content, not the name; another format (GIF, AVIF, ...) is refused with the list of these.

use std::io::Cursor;
use std::path::Path;

use image::{DynamicImage, ImageEncoder, ImageReader};

use crate::error::{Error, Result};
use crate::image::{DisparityMap, Plane, RgbImage};

/// The image formats jem reads, as an error message lists them.
pub const IMAGE_FORMATS: &str = "PNG, PPM/PGM/PNM, JPEG, BMP, TIFF, WebP";

/// Refuses a file whose format was not recognised, or is one the decoder was not built to read, naming the file
/// and listing the formats that are read (the decoder's own message names neither).
fn check_format<R>(path: &Path, reader: &ImageReader<R>) -> Result<()>
where
    R: std::io::BufRead + std::io::Seek,
{
    match reader.format() {
        Some(f) if f.reading_enabled() => Ok(()),
        Some(f) => Err(Error::bad_image_at(
            path,
            format!(
                "{} images are not read (supported: {IMAGE_FORMATS})",
                f.extensions_str().first().map_or("these", |e| e).to_ascii_uppercase()
            ),
        )),
        None => Err(Error::bad_image_at(path, format!("not an image jem reads (supported: {IMAGE_FORMATS})"))),
    }
}

/// What an image file's header says, read without decoding the image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageHeader {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// The memory `load_rgb` holds at its peak: the file, the decoded samples and the `f32` planes.
    pub load_bytes: u64,
}

/// Reads the header of an image file (not the image).
///
/// # Errors
/// As [`load_rgb`], for the header.
pub(crate) fn read_header(path: &Path) -> Result<ImageHeader> {
    let (width, height, file_bytes, sample_bytes) = header_parts(path)?;
    let px = width as u64 * height as u64;
    let load_bytes = file_bytes.saturating_add(sample_bytes).saturating_add(12 * px);
    Ok(ImageHeader { width, height, load_bytes })
}

/// An image file's size (width, height), its length in bytes and the bytes of its decoded samples (at its own bit
/// depth and channels), from the header.
fn header_parts(path: &Path) -> Result<(usize, usize, u64, u64)> {
    use image::ImageDecoder;
    let (decoder, file_bytes) = header_decoder(path)?;
    let (w, h) = decoder.dimensions();
    Ok((w as usize, h as usize, file_bytes, decoder.total_bytes()))
}

/// Whether an image file holds grey samples (grey or grey + alpha, at any depth), from its header.
///
/// # Errors
/// As [`read_header`].
pub(crate) fn is_grey(path: &Path) -> Result<bool> {
    use image::ImageDecoder;
    let color = header_decoder(path)?.0.color_type();
    Ok(matches!(color, image::ColorType::L8 | image::ColorType::La8 | image::ColorType::L16 | image::ColorType::La16))
}

/// An image file's decoder, its header read (not the image), and the file's length in bytes.
fn header_decoder(path: &Path) -> Result<(impl image::ImageDecoder, u64)> {
    let file = super::open_regular(path)?;
    let file_bytes = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let reader = ImageReader::new(std::io::BufReader::new(file));
    let reader = reader.with_guessed_format().map_err(|e| Error::io(path, e))?;
    check_format(path, &reader)?;
    let decoder = reader.into_decoder().map_err(|source| Error::Image { path: path.to_path_buf(), source })?;
    Ok((decoder, file_bytes))
}

/// [`decode`] within `max_bytes`: from the header, the file, its decoded samples and a converted copy of them
/// (what a caller converting the samples holds) must fit, else nothing is decoded (a small file may declare a
/// huge image); the decoder is held to the limit too.
///
/// # Errors
/// As [`decode`]; [`Error::OutOfMemory`] naming the file when its decoding does not fit.
pub(crate) fn decode_bounded(path: &Path, max_bytes: u64) -> Result<DynamicImage> {
    let (w, h, file_bytes, sample_bytes) = header_parts(path)?;
    let need = file_bytes.saturating_add(sample_bytes.saturating_mul(2));
    if need > max_bytes {
        return Err(Error::OutOfMemory {
            needed: need,
            limit: max_bytes,
            hint: format!("{}: decoding its {w}x{h} image does not fit; raise the memory limit", path.display()),
        });
    }
    decode_within(path, Some(max_bytes))
}

/// Reads the headers of both images of a pair, before either is decoded: their common size and the memory
/// [`load_rgb_pair`] holds at its peak (both loads at once).
///
/// # Errors
/// As [`read_header`]; [`Error::SizeMismatch`] for unequal sizes, [`Error::InputImage`] for empty images or images
/// narrower than 2 pixels (no disparity range fits them).
pub(crate) fn read_pair_header(left: &Path, right: &Path) -> Result<ImageHeader> {
    let (l, r) = (read_header(left)?, read_header(right)?);
    if (l.width, l.height) != (r.width, r.height) {
        return Err(Error::SizeMismatch { left: (l.width, l.height), right: (r.width, r.height) });
    }
    if l.width == 0 || l.height == 0 {
        return Err(Error::bad_image_at(left, "the images are empty (0 pixels)"));
    }
    if l.width < 2 {
        return Err(Error::bad_image_at(
            left,
            format!("the images are {}x{}; a stereo pair must be at least 2 pixels wide", l.width, l.height),
        ));
    }
    Ok(ImageHeader { load_bytes: l.load_bytes.saturating_add(r.load_bytes), ..l })
}

/// Loads the two images of a pair at the same time (see [`load_rgb`]).
///
/// # Errors
/// As [`load_rgb`]; the left image's error is reported if both fail.
pub(crate) fn load_rgb_pair(left: &Path, right: &Path) -> Result<(RgbImage, RgbImage)> {
    let (l, r) = rayon::join(|| load_rgb(left), || load_rgb(right));
    Ok((l?, r?))
}

/// [`load_rgb_pair`] with the decoder's own allocation limit set to `max_bytes` (the memory limit the pair was
/// checked against from its headers, [`read_pair_header`]), instead of the decoder's default of 512 MiB, which
/// refused large images with "Memory limit exceeded" whatever `--max-memory` said.
///
/// # Errors
/// As [`load_rgb_pair`].
pub(crate) fn load_rgb_pair_within(left: &Path, right: &Path, max_bytes: u64) -> Result<(RgbImage, RgbImage)> {
    let (l, r) = rayon::join(|| load_rgb_within(left, Some(max_bytes)), || load_rgb_within(right, Some(max_bytes)));
    Ok((l?, r?))
}

/// Loads an image file as planar RGB `f32` in 0..=255.
///
/// # Errors
/// [`Error::Io`] if the file cannot be opened, [`Error::Image`] (naming the file and the decoder's reason) if it
/// is not a readable image in one of [`IMAGE_FORMATS`].
pub(crate) fn load_rgb(path: &Path) -> Result<RgbImage> {
    load_rgb_within(path, None)
}

/// [`load_rgb`], with the decoder's allocation limit `max_bytes` (`None`: the decoder's default).
fn load_rgb_within(path: &Path, max_bytes: Option<u64>) -> Result<RgbImage> {
    Ok(to_rgb(&decode_within(path, max_bytes)?))
}

/// Decodes an image file as it is (bit depth and channels kept).
///
/// # Errors
/// As [`load_rgb`].
pub(crate) fn decode(path: &Path) -> Result<DynamicImage> {
    decode_within(path, None)
}

/// [`decode`], with the decoder's allocation limit `max_bytes` (`None`: the decoder's default).
fn decode_within(path: &Path, max_bytes: Option<u64>) -> Result<DynamicImage> {
    let bytes = super::read_regular(path)?;
    let mut reader = ImageReader::new(Cursor::new(bytes)).with_guessed_format().map_err(|e| Error::io(path, e))?;
    check_format(path, &reader)?;
    if let Some(max) = max_bytes {
        let mut limits = image::Limits::default();
        limits.max_alloc = Some(max);
        reader.limits(limits);
    }
    let img = reader.decode().map_err(|source| Error::Image { path: path.to_path_buf(), source })?;
    check_float_samples(path, &img)?;
    Ok(img)
}

/// Refuses a floating-point image (TIFF's float samples) whose colour samples leave the 0..1 scale they are read
/// on: grey levels 0..255 stored as floats would all be clipped to white, and a NaN read as white too.
fn check_float_samples(path: &Path, img: &DynamicImage) -> Result<()> {
    let (samples, channels) = match img {
        DynamicImage::ImageRgb32F(b) => (b.as_raw(), 3),
        DynamicImage::ImageRgba32F(b) => (b.as_raw(), 4),
        _ => return Ok(()),
    };
    let colour = samples.chunks_exact(channels).flat_map(|px| &px[..3]);
    match colour.copied().find(|v| !(0.0..=1.0).contains(v)) {
        None => Ok(()),
        Some(v) => Err(Error::bad_image_at(
            path,
            format!(
                "a floating-point image with a sample {v} outside 0..1; jem reads float samples on the 0..1 scale \
             (save the image with 8- or 16-bit samples, or scale it to 0..1)"
            ),
        )),
    }
}

/// Converts a decoded image to planar RGB `f32` (0..=255).
pub(crate) fn to_rgb(img: &DynamicImage) -> RgbImage {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let mut out = RgbImage::new(w, h);
    let mut put = |i: usize, rgb: [f32; 3]| {
        for (c, v) in rgb.into_iter().enumerate() {
            out.channels[c][i] = v;
        }
    };
    match img {
        DynamicImage::ImageRgb8(b) => {
            b.pixels().enumerate().for_each(|(i, p)| put(i, p.0.map(f32::from)));
        }
        DynamicImage::ImageLuma8(b) => {
            b.pixels().enumerate().for_each(|(i, p)| put(i, [f32::from(p.0[0]); 3]));
        }
        DynamicImage::ImageRgba8(b) => {
            b.pixels().enumerate().for_each(|(i, p)| put(i, [p.0[0], p.0[1], p.0[2]].map(f32::from)));
        }
        DynamicImage::ImageLumaA8(b) => {
            b.pixels().enumerate().for_each(|(i, p)| put(i, [f32::from(p.0[0]); 3]));
        }
        other => {
            // 16-bit and float variants: go through 16-bit RGB and rescale to the 8-bit range.
            let b = other.to_rgb16();
            b.pixels().enumerate().for_each(|(i, p)| put(i, p.0.map(|v| f32::from(v) / 257.0)));
        }
    }
    out
}

/// Writes an 8-bit RGB PNG (interleaved `rgb`, `width * height * 3` bytes) atomically.
///
/// # Errors
/// [`Error::Image`] or [`Error::Io`] naming the path.
///
/// # Panics
/// If `rgb.len() != width * height * 3`.
pub(crate) fn write_rgb8_png(path: &Path, width: usize, height: usize, rgb: &[u8]) -> Result<()> {
    super::write_atomic(path, &encode_rgb8_png(path, width, height, rgb)?)
}

/// An 8-bit RGB PNG's bytes (interleaved `rgb`, `width * height * 3` bytes); `path` names it in errors.
///
/// # Errors
/// [`Error::Image`] naming the path.
///
/// # Panics
/// If `rgb.len() != width * height * 3`.
pub(crate) fn encode_rgb8_png(path: &Path, width: usize, height: usize, rgb: &[u8]) -> Result<Vec<u8>> {
    assert_eq!(rgb.len(), width * height * 3);
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(rgb, width as u32, height as u32, image::ExtendedColorType::Rgb8)
        .map_err(|source| Error::Image { path: path.to_path_buf(), source })?;
    Ok(bytes)
}

/// An 8-bit grey PNG's bytes (`width * height` samples, row-major); `path` names it in errors.
///
/// # Errors
/// [`Error::Image`] naming the path.
///
/// # Panics
/// If `grey.len() != width * height`.
pub(crate) fn encode_grey8_png(path: &Path, width: usize, height: usize, grey: &[u8]) -> Result<Vec<u8>> {
    assert_eq!(grey.len(), width * height);
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(grey, width as u32, height as u32, image::ExtendedColorType::L8)
        .map_err(|source| Error::Image { path: path.to_path_buf(), source })?;
    Ok(bytes)
}

/// The largest disparity a 16-bit PNG holds: 65535 / 256.
pub const PNG16_MAX_DISPARITY: f32 = 65535.0 / 256.0;

/// A disparity map encoded as a 16-bit grey PNG, value = round(d × 256), 0 = invalid (KITTI convention).
/// A disparity of 0 is stored as 1/256 (0 means invalid); negative and non-finite ones become 0 (invalid).
///
/// # Errors
/// [`Error::Output`] naming the path if a disparity exceeds [`PNG16_MAX_DISPARITY`] (nothing is written: the
/// format cannot hold it; `.pfm` or `.exr` can); [`Error::Image`] or [`Error::Io`] naming the path.
pub(crate) fn encode_disparity_png16(path: &Path, map: &DisparityMap) -> Result<Vec<u8>> {
    if let Some(max) = map.data.iter().copied().filter(|d| d.is_finite()).reduce(f32::max)
        && max * 256.0 > 65535.5
    {
        return Err(Error::output_at(
            path,
            format!(
                "disparity {max} does not fit a 16-bit PNG (at most {:.3}); write .pfm or .exr instead",
                PNG16_MAX_DISPARITY
            ),
        ));
    }
    let value = |d: f32| if d.is_finite() && d >= 0.0 { (d * 256.0).round().clamp(1.0, 65535.0) as u16 } else { 0 };
    encode_grey16_png(path, map, value)
}

/// `map` as a 16-bit grey PNG, each value `value(v)`.
fn encode_grey16_png(path: &Path, map: &Plane<f32>, value: impl Fn(f32) -> u16) -> Result<Vec<u8>> {
    // The encoder takes 16-bit samples in native byte order (it writes them big-endian itself).
    let samples: Vec<u8> = map.data.iter().flat_map(|&v| value(v).to_ne_bytes()).collect();
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(&samples, map.width as u32, map.height as u32, image::ExtendedColorType::L16)
        .map_err(|source| Error::Image { path: path.to_path_buf(), source })?;
    Ok(bytes)
}

/// A depth map encoded as a 16-bit grey PNG, the depth in the baseline's unit rounded to a whole unit, 0 = invalid
/// (the RealSense and ZED convention: millimetres for a baseline in millimetres). `inf`, NaN and depths of 0 or
/// less are invalid.
///
/// # Errors
/// [`Error::Output`] naming the path, nothing written, when a depth rounds above 65535 (the format cannot hold it;
/// the message says how far the depths go) or a valid depth rounds to 0 (it would read as invalid: the unit is too
/// coarse); [`Error::Image`] naming the path.
pub(crate) fn encode_depth_png16(path: &Path, depth: &Plane<f32>) -> Result<Vec<u8>> {
    let valid = || depth.data.iter().copied().filter(|z| z.is_finite() && *z > 0.0);
    let refuse = |why: String| Err(Error::output_at(path, why));
    if let Some(max) = valid().reduce(f32::max).filter(|&z| z.round() > 65535.0) {
        return refuse(format!(
            "depth {max:.0} (the baseline's unit) does not fit a 16-bit PNG (at most 65535): leave the farther \
             points out (--max-depth 65535), give the baseline in a larger unit, or write .pfm or .exr"
        ));
    }
    if let Some(min) = valid().reduce(f32::min).filter(|&z| z.round() < 1.0) {
        return refuse(format!(
            "depth {min} (the baseline's unit) rounds to 0, which a depth PNG reads as invalid: give the baseline in \
             a smaller unit (millimetres), or write .pfm or .exr"
        ));
    }
    encode_grey16_png(path, depth, |z| if z.is_finite() && z > 0.0 { z.round() as u16 } else { 0 })
}

/// Reads a 16-bit disparity PNG (value / 256, 0 = invalid → inf).
///
/// # Errors
/// [`Error::Io`] or [`Error::Image`] naming the path.
pub(crate) fn read_disparity_png16(path: &Path) -> Result<DisparityMap> {
    read_png16(path, 256.0)
}

/// Reads a 16-bit depth PNG as `jem --depth` writes it (the depth in the baseline's unit, 0 = invalid → inf).
///
/// # Errors
/// As [`read_disparity_png16`].
pub(crate) fn read_depth_png16(path: &Path) -> Result<Plane<f32>> {
    read_png16(path, 1.0)
}

/// Reads a one-channel 16-bit PNG as values / `unit` (0 = invalid → inf).
fn read_png16(path: &Path, unit: f32) -> Result<Plane<f32>> {
    let bytes = super::read_regular(path)?;
    let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
        .map_err(|source| Error::Image { path: path.to_path_buf(), source })?;
    // A disparity PNG is one 16-bit channel (KITTI convention); an 8-bit or colour image is a picture, and
    // reading it as disparities would give plausible-looking nonsense.
    if img.color() != image::ColorType::L16 {
        return Err(Error::bad_image_at(
            path,
            format!(
                "a {:?} PNG is not a disparity map (expected 16-bit grey, disparity × 256; or use .pfm/.exr)",
                img.color()
            ),
        ));
    }
    let grey = img.to_luma16();
    let data = grey.pixels().map(|p| if p.0[0] == 0 { f32::INFINITY } else { f32::from(p.0[0]) / unit }).collect();
    Ok(Plane::from_parts(grey.width() as usize, grey.height() as usize, data))
}

/// Loads an 8-bit grey image (e.g. `mask0nocc.png`) as a plane of `u8`.
///
/// # Errors
/// [`Error::Io`] or [`Error::Image`] naming the path.
pub(crate) fn load_grey8(path: &Path) -> Result<Plane<u8>> {
    let bytes = super::read_regular(path)?;
    let img = image::load_from_memory(&bytes).map_err(|source| Error::Image { path: path.to_path_buf(), source })?;
    let grey = img.to_luma8();
    Ok(Plane::from_parts(grey.width() as usize, grey.height() as usize, grey.into_raw()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A depth PNG holds the depth rounded to a whole unit, 0 where there is none; a depth above 65535 or one that
    /// would round to 0 is refused, naming the file.
    #[test]
    fn a_depth_png_holds_whole_units_and_refuses_what_it_cannot() {
        let (inf, nan) = (f32::INFINITY, f32::NAN);
        let depth = Plane::from_parts(3, 2, vec![1.0, 1234.4, 65535.4, inf, nan, -3.0]);
        let bytes = encode_depth_png16(Path::new("z.png"), &depth).unwrap();
        let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png).unwrap();
        assert_eq!(img.color(), image::ColorType::L16);
        assert_eq!(img.to_luma16().into_raw(), [1, 1234, 65535, 0, 0, 0]);
        let too_far = Plane::from_parts(2, 1, vec![100.0, 65535.6]);
        let e = encode_depth_png16(Path::new("far.png"), &too_far).unwrap_err().to_string();
        assert!(e.starts_with("far.png: depth 65536") && e.contains("--max-depth 65535"), "{e}");
        let too_near = Plane::from_parts(2, 1, vec![0.4, 3.0]);
        let e = encode_depth_png16(Path::new("near.png"), &too_near).unwrap_err().to_string();
        assert!(e.starts_with("near.png: depth 0.4") && e.contains("rounds to 0"), "{e}");
    }

    #[test]
    fn loads_all_pixel_layouts_to_the_same_rgb() {
        let dir = tempfile::tempdir().unwrap();
        let rgb8 = image::RgbImage::from_fn(3, 2, |x, y| image::Rgb([(x * 80) as u8, (y * 100) as u8, 7]));
        let p8 = dir.path().join("a.png");
        rgb8.save(&p8).unwrap();
        let p16 = dir.path().join("b.png");
        DynamicImage::ImageRgb8(rgb8.clone()).to_rgb16().save(&p16).unwrap();
        let pa = dir.path().join("c.png");
        DynamicImage::ImageRgb8(rgb8.clone()).to_rgba8().save(&pa).unwrap();
        let ppm = dir.path().join("d.ppm");
        rgb8.save(&ppm).unwrap();
        let a = load_rgb(&p8).unwrap();
        assert_eq!(a.dims(), (3, 2));
        assert_eq!(a.rgb(5), [160.0, 100.0, 7.0]);
        for p in [&p16, &pa, &ppm] {
            assert_eq!(load_rgb(p).unwrap(), a, "{}", p.display());
        }
        let grey = dir.path().join("g.pgm");
        image::GrayImage::from_pixel(2, 2, image::Luma([9])).save(&grey).unwrap();
        assert_eq!(load_rgb(&grey).unwrap().rgb(3), [9.0; 3]);
    }

    #[test]
    fn bmp_tiff_and_lossless_webp_read_as_the_png() {
        let dir = tempfile::tempdir().unwrap();
        let rgb8 = image::RgbImage::from_fn(5, 3, |x, y| image::Rgb([(x * 50) as u8, (y * 90) as u8, 200]));
        let png = dir.path().join("a.png");
        rgb8.save(&png).unwrap();
        let want = load_rgb(&png).unwrap();
        let tiff8 = dir.path().join("b.tif");
        rgb8.save(&tiff8).unwrap();
        let tiff16 = dir.path().join("b16.tiff");
        DynamicImage::ImageRgb8(rgb8.clone()).to_rgb16().save(&tiff16).unwrap();
        let webp = dir.path().join("c.webp");
        DynamicImage::ImageRgb8(rgb8.clone()).to_rgba8().save(&webp).unwrap();
        // Named .img: the content tells the format, not the name.
        let bmp = dir.path().join("d.img");
        rgb8.save_with_format(&bmp, image::ImageFormat::Bmp).unwrap();
        for p in [tiff8, tiff16, webp, bmp] {
            assert_eq!(load_rgb(&p).unwrap(), want, "{}", p.display());
            let h = read_header(&p).unwrap();
            assert_eq!((h.width, h.height), (5, 3), "{}", p.display());
        }
    }

    #[test]
    fn an_unsupported_format_lists_the_supported_ones() {
        let dir = tempfile::tempdir().unwrap();
        let gif = dir.path().join("x.gif");
        std::fs::write(&gif, b"GIF89a\x01\x00\x01\x00\x00\x00\x00;").unwrap();
        for e in [load_rgb(&gif).unwrap_err(), read_header(&gif).unwrap_err()] {
            let msg = e.to_string();
            assert!(msg.contains("x.gif") && msg.contains("GIF") && msg.contains(IMAGE_FORMATS), "{msg}");
        }
        let text = dir.path().join("t.png");
        std::fs::write(&text, b"hello").unwrap();
        assert!(load_rgb(&text).unwrap_err().to_string().contains("supported: PNG"));
    }

    #[test]
    fn corrupt_and_missing_files_name_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("nope.png");
        assert!(load_rgb(&missing).unwrap_err().to_string().contains("nope.png"));
        let bad = dir.path().join("bad.png");
        std::fs::write(&bad, b"\x89PNG\r\n\x1a\nnot really").unwrap();
        assert!(load_rgb(&bad).unwrap_err().to_string().contains("bad.png"));
        let text = dir.path().join("t.png");
        std::fs::write(&text, b"hello").unwrap();
        assert!(load_rgb(&text).unwrap_err().to_string().contains("t.png"));
    }

    /// A float TIFF is read on the 0..1 scale; one whose samples leave it (grey levels 0..255 stored as floats,
    /// which were all clipped to white) or are not numbers (read as white) is refused, naming the file.
    #[test]
    fn float_tiffs_outside_zero_to_one_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let save = |name: &str, f: &dyn Fn(u32) -> f32| {
            let img = image::Rgb32FImage::from_fn(4, 2, |x, y| image::Rgb([f(x + 4 * y); 3]));
            let path = dir.path().join(name);
            DynamicImage::ImageRgb32F(img).save(&path).unwrap();
            path
        };
        let unit = save("unit.tif", &|i| i as f32 / 7.0);
        let read = load_rgb(&unit).unwrap();
        let want = (65535.0 * 3.0 / 7.0f32).round() / 257.0;
        assert!((read.rgb(3)[0] - want).abs() < 1e-3, "{:?}", read.rgb(3));
        for (name, f, shown) in [
            ("grey.tif", &(|i: u32| 30.0 * i as f32) as &dyn Fn(u32) -> f32, "30"),
            ("nan.tif", &|_| f32::NAN, "NaN"),
            ("negative.tif", &|i| i as f32 / 7.0 - 0.5, "-0.5"),
        ] {
            let path = save(name, f);
            for e in [load_rgb(&path).unwrap_err(), decode(&path).unwrap_err()] {
                let msg = e.to_string();
                assert!(msg.contains(name) && msg.contains(shown) && msg.contains("outside 0..1"), "{msg}");
            }
        }
    }

    #[test]
    fn disparity_png16_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.png");
        let map = Plane::from_parts(2, 2, vec![0.5, 100.25, f32::INFINITY, -1.0]);
        crate::io::write_disparity(&p, &map).unwrap();
        let back = read_disparity_png16(&p).unwrap();
        assert_eq!(back.data[..2], [0.5, 100.25]);
        assert!(back.data[2].is_infinite() && back.data[3].is_infinite());
    }
}
