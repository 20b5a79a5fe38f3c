//! Seeded degradations of a stereo pair, the measuring stick for robustness (`jem degrade`): sensor noise, low
//! light, an exposure and gamma mismatch between the views, and blur, applied to 8-bit images as a camera would
//! produce them (the result is rounded to 8 bits again, so quantisation is part of the degradation).
//!
//! Every degradation is a pure function of the input images, its parameters and a seed: the same call writes the
//! same bytes. The two views get independent noise (different streams of one seed).
//!
//! The models, in grey levels of the 8-bit input (0..=255):
//! - `noise:S` — additive Gaussian noise of standard deviation S on every channel of both views;
//! - `lowlight:G:R` — the light scaled by G (0 < G ≤ 1), the 8-bit values taken as linear in the light (a raw,
//!   linear sensor response), with photon shot noise (variance equal to the signal in electrons, a full-scale
//!   pixel holding 255 × 16 electrons) and read noise of R grey levels, and no gain applied afterwards: a dark
//!   image whose values span 0..255·G, as a camera without auto-exposure gives;
//! - `exposure:G:P` — the right view only: v ↦ 255·(G·v/255)^P (a darker or brighter view with another tone
//!   curve); Census is invariant to it, the gradient term and colour weights are not;
//! - `blur:S` — a Gaussian blur of standard deviation S pixels on both views (defocus);
//! - `misalign:D:A` — the right view only, moved down by D pixels and rotated by A degrees (counter-clockwise)
//!   about its centre, bilinear: an imperfectly rectified rig (the ground truth is left as it is, so a rotation
//!   also moves matches horizontally, which no matcher can undo);
//! - `jpeg:Q` — JPEG compression of both views at quality Q (1–100; the `image` crate's baseline encoder);
//! - several degradations separated by `+` apply in order (e.g. `blur:1+noise:4`);
//! - `none` leaves the images as they are (a clean sequence with `--frames`).
//!
//! [`degrade_tree`] makes a degraded copy of a whole MiddEval3-style tree (every scene folder with `im0.png`,
//! `im1.png` and `calib.txt`): the images degraded, the ground truth, masks and calibration copied unchanged, so
//! `jem batch` and `jem eval` run on it as on the original.

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use rayon::prelude::*;

use crate::dataset::{CALIB_FILE, GT_FILE, LEFT_FILE, MASK_FILE, RIGHT_FILE};
use crate::error::{Error, Result};
use crate::image::RgbImage;
use crate::imgproc::filter::gaussian_blur;
use crate::rng::SplitMix64;

/// One degradation step (see the module doc for the models).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Degradation {
    /// Additive Gaussian noise, σ in grey levels, both views.
    Noise {
        /// Standard deviation in grey levels.
        sigma: f64,
    },
    /// Less light: linear intensity × `gain`, shot noise and read noise, no gain applied afterwards.
    LowLight {
        /// The fraction of the light that remains (0 < gain ≤ 1).
        gain: f64,
        /// Read noise in grey levels.
        read_sigma: f64,
    },
    /// The right view's tone curve changed: v ↦ 255·(gain·v/255)^gamma.
    Exposure {
        /// Multiplies the right view's intensity before the power.
        gain: f64,
        /// The power applied to the scaled, normalised intensity.
        gamma: f64,
    },
    /// Gaussian blur of both views.
    Blur {
        /// Standard deviation in pixels.
        sigma: f64,
    },
    /// Imperfect rectification: the right view moved down by `dy` pixels and rotated by `degrees` about its
    /// centre (bilinear, borders replicated).
    Misalign {
        /// Vertical shift in pixels (positive: the content moves down).
        dy: f64,
        /// Rotation in degrees (positive: counter-clockwise on screen).
        degrees: f64,
    },
    /// JPEG compression of both views (encoded with the `image` crate's baseline encoder and decoded again).
    Jpeg {
        /// Quality, 1 (worst) to 100.
        quality: u8,
    },
}

/// A chain of degradations, applied in order; parsed from `step+step+…`.
#[derive(Clone, Debug, PartialEq)]
pub struct Recipe(pub Vec<Degradation>);

/// Electrons of a full-scale (255) pixel in the low-light model: sets how strong shot noise is.
const FULL_WELL_ELECTRONS: f64 = 255.0 * 16.0;

impl FromStr for Degradation {
    type Err = Error;

    fn from_str(text: &str) -> std::result::Result<Self, Error> {
        Degradation::parse_step(text).map_err(Error::argument)
    }
}

impl Degradation {
    /// [`Degradation::from_str`], with the message alone.
    fn parse_step(text: &str) -> std::result::Result<Self, String> {
        let mut parts = text.split(':');
        let kind = parts.next().unwrap_or_default();
        let args: Vec<&str> = parts.collect();
        let num = |k: usize, name: &str| -> std::result::Result<f64, String> {
            let s = args.get(k).ok_or_else(|| format!("`{text}`: missing {name} (expected {})", usage(kind)))?;
            s.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("`{text}`: {name} `{s}` is not a finite number"))
        };
        let arity = |n: usize| {
            if args.len() == n { Ok(()) } else { Err(format!("`{text}`: expected {}", usage(kind))) }
        };
        let step = match kind {
            "noise" => {
                arity(1)?;
                Degradation::Noise { sigma: num(0, "sigma")? }
            }
            "lowlight" => {
                arity(2)?;
                Degradation::LowLight { gain: num(0, "gain")?, read_sigma: num(1, "read noise")? }
            }
            "exposure" => {
                arity(2)?;
                Degradation::Exposure { gain: num(0, "gain")?, gamma: num(1, "gamma")? }
            }
            "blur" => {
                arity(1)?;
                Degradation::Blur { sigma: num(0, "sigma")? }
            }
            "misalign" => {
                arity(2)?;
                Degradation::Misalign { dy: num(0, "shift")?, degrees: num(1, "rotation")? }
            }
            "jpeg" => {
                arity(1)?;
                let q = num(0, "quality")?;
                if q.fract() != 0.0 || !(1.0..=100.0).contains(&q) {
                    return Err(format!("`{text}`: quality must be a whole number 1 to 100"));
                }
                Degradation::Jpeg { quality: q as u8 }
            }
            _ => {
                return Err(format!(
                    "unknown degradation `{kind}` (expected noise, lowlight, exposure, blur, misalign or jpeg)"
                ));
            }
        };
        step.validate().map_err(|e| format!("`{text}`: {e}"))?;
        Ok(step)
    }
}

/// The form of each degradation, for error messages.
fn usage(kind: &str) -> &'static str {
    match kind {
        "noise" => "noise:SIGMA",
        "lowlight" => "lowlight:GAIN:READ_SIGMA",
        "exposure" => "exposure:GAIN:GAMMA",
        "blur" => "blur:SIGMA",
        "misalign" => "misalign:SHIFT:DEGREES",
        "jpeg" => "jpeg:QUALITY",
        _ => "noise:S, lowlight:G:R, exposure:G:P, blur:S, misalign:DY:DEG or jpeg:Q",
    }
}

impl Degradation {
    fn validate(&self) -> std::result::Result<(), String> {
        let ok = match *self {
            Degradation::Noise { sigma } | Degradation::Blur { sigma } => (0.0..=100.0).contains(&sigma),
            Degradation::LowLight { gain, read_sigma } => {
                gain > 0.0 && gain <= 1.0 && (0.0..=100.0).contains(&read_sigma)
            }
            Degradation::Exposure { gain, gamma } => gain > 0.0 && gain <= 10.0 && gamma > 0.0 && gamma <= 10.0,
            Degradation::Misalign { dy, degrees } => dy.abs() <= 100.0 && degrees.abs() <= 45.0,
            Degradation::Jpeg { quality } => (1..=100).contains(&quality),
        };
        if ok {
            Ok(())
        } else {
            Err("out of range (sigma 0..=100, gain 0 < g ≤ 1 for lowlight and ≤ 10 for exposure, gamma 0 < p ≤ 10, \
                 shift ±100 px, rotation ±45°)"
                .to_string())
        }
    }
}

impl fmt::Display for Degradation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Degradation::Noise { sigma } => write!(f, "noise:{sigma}"),
            Degradation::LowLight { gain, read_sigma } => write!(f, "lowlight:{gain}:{read_sigma}"),
            Degradation::Exposure { gain, gamma } => write!(f, "exposure:{gain}:{gamma}"),
            Degradation::Blur { sigma } => write!(f, "blur:{sigma}"),
            Degradation::Misalign { dy, degrees } => write!(f, "misalign:{dy}:{degrees}"),
            Degradation::Jpeg { quality } => write!(f, "jpeg:{quality}"),
        }
    }
}

impl FromStr for Recipe {
    type Err = Error;

    fn from_str(text: &str) -> std::result::Result<Self, Error> {
        if text == "none" {
            return Ok(Recipe(Vec::new()));
        }
        let steps = text.split('+').map(str::parse).collect::<std::result::Result<Vec<_>, _>>()?;
        Ok(Recipe(steps))
    }
}

impl fmt::Display for Recipe {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.is_empty() {
            return f.write_str("none");
        }
        for (k, step) in self.0.iter().enumerate() {
            if k > 0 {
                f.write_str("+")?;
            }
            write!(f, "{step}")?;
        }
        Ok(())
    }
}

/// Which view an image is (the views get independent noise; exposure changes the right one only).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum View {
    /// The left (reference) view.
    Left,
    /// The right view.
    Right,
}

/// Applies `recipe` to one view, with noise drawn from `seed` (and the view, and the step's position).
///
/// # Errors
/// Never for a valid recipe; `InvalidParam` for a step out of range (a recipe built by hand).
pub fn degrade(image: &RgbImage, recipe: &Recipe, view: View, seed: u64) -> Result<RgbImage> {
    let mut img = image.clone();
    for (k, step) in recipe.0.iter().enumerate() {
        step.validate().map_err(|e| Error::InvalidParam {
            name: "degradation".into(),
            value: step.to_string(),
            expected: e,
        })?;
        let stream = seed ^ ((k as u64 + 1) << 40) ^ if view == View::Right { 0x9e37_79b9_7f4a_7c15 } else { 0 };
        img = apply(&img, *step, view, stream);
    }
    Ok(img)
}

fn apply(image: &RgbImage, step: Degradation, view: View, seed: u64) -> RgbImage {
    let mut out = image.clone();
    let mut rng = Gaussian::new(seed);
    match step {
        Degradation::Noise { sigma } => {
            for ch in &mut out.channels {
                ch.iter_mut().for_each(|v| *v = quantise(f64::from(*v) + sigma * rng.sample()));
            }
        }
        Degradation::LowLight { gain, read_sigma } => {
            for ch in &mut out.channels {
                ch.iter_mut().for_each(|v| {
                    let electrons = f64::from(*v) / 255.0 * gain * FULL_WELL_ELECTRONS;
                    let shot = electrons.sqrt() * rng.sample();
                    let signal = (electrons + shot) / FULL_WELL_ELECTRONS * 255.0;
                    *v = quantise(signal + read_sigma * rng.sample());
                });
            }
        }
        Degradation::Exposure { gain, gamma } => {
            if view == View::Right {
                for ch in &mut out.channels {
                    ch.iter_mut().for_each(|v| {
                        *v = quantise(255.0 * (gain * f64::from(*v) / 255.0).clamp(0.0, 1.0).powf(gamma));
                    });
                }
            }
        }
        Degradation::Blur { sigma } => {
            out = gaussian_blur(image, sigma as f32);
            for ch in &mut out.channels {
                ch.iter_mut().for_each(|v| *v = quantise(f64::from(*v)));
            }
        }
        Degradation::Misalign { dy, degrees } => {
            if view == View::Right {
                out = misalign(image, dy, degrees);
            }
        }
        Degradation::Jpeg { quality } => out = jpeg_round_trip(image, quality),
    }
    out
}

/// The image moved down by `dy` pixels and rotated by `degrees` (counter-clockwise on screen) about its centre:
/// each output pixel samples the input bilinearly at the inverse transform ([`sample_bilinear`](crate::imgproc::sample::sample_bilinear),
/// coordinates clamped to the image), rounded to 8 bits.
fn misalign(image: &RgbImage, dy: f64, degrees: f64) -> RgbImage {
    let (w, h) = image.dims();
    let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
    let (sin, cos) = degrees.to_radians().sin_cos();
    let mut out = RgbImage::new(w, h);
    for y in 0..h {
        for x in 0..w {
            // Undo the shift, then the rotation (y points down, so counter-clockwise on screen is −θ in these
            // coordinates).
            let (px, py) = (x as f64 - cx, y as f64 - dy - cy);
            let (sx, sy) = (cos * px - sin * py + cx, sin * px + cos * py + cy);
            for (src, dst) in image.channels.iter().zip(out.channels.iter_mut()) {
                dst[y * w + x] = quantise(crate::imgproc::sample::sample_bilinear(src, w, h, sx, sy));
            }
        }
    }
    out
}

/// The image encoded as a baseline JPEG of `quality` and decoded again (deterministic: a pure function of the
/// pixels).
fn jpeg_round_trip(image: &RgbImage, quality: u8) -> RgbImage {
    let (w, h) = image.dims();
    let mut rgb = Vec::with_capacity(w * h * 3);
    for i in 0..w * h {
        rgb.extend(image.rgb(i).map(|v| v.round().clamp(0.0, 255.0) as u8));
    }
    let mut bytes = Vec::new();
    let encoded = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, quality).encode(
        &rgb,
        w as u32,
        h as u32,
        image::ExtendedColorType::Rgb8,
    );
    let decoded = encoded.ok().and_then(|()| image::load_from_memory(&bytes).ok());
    // An encoder failure (impossible for a valid 8-bit RGB buffer) leaves the image as it is.
    decoded.map_or_else(|| image.clone(), |d| crate::io::png::to_rgb(&d))
}

/// Rounds to the nearest 8-bit level, clamped to 0..=255.
fn quantise(v: f64) -> f32 {
    v.round().clamp(0.0, 255.0) as f32
}

/// Standard normal samples (Box–Muller on a [`SplitMix64`] stream).
struct Gaussian {
    rng: SplitMix64,
    spare: Option<f64>,
}

impl Gaussian {
    fn new(seed: u64) -> Self {
        Gaussian { rng: SplitMix64::new(seed), spare: None }
    }

    fn uniform(&mut self) -> f64 {
        self.rng.next_f64()
    }

    fn sample(&mut self) -> f64 {
        if let Some(v) = self.spare.take() {
            return v;
        }
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let t = std::f64::consts::TAU * u2;
        self.spare = Some(r * t.sin());
        r * t.cos()
    }
}

/// Files copied unchanged into each degraded scene, when the source scene has them.
pub const COPIED_FILES: [&str; 5] = [CALIB_FILE, GT_FILE, MASK_FILE, "disp1GT.pfm", "mask1nocc.png"];

/// Makes a degraded copy of every scene under `src` in the new folder `out` (same relative paths; a `src` that
/// is itself a scene becomes `out/NAME`), and writes `out/degrade.txt` with the recipe, seed and jem version.
/// Each scene's noise comes from `seed` and the scene's relative path, so scenes differ and a rerun is
/// byte-identical. The tree is built in a temporary sibling folder and renamed into place at the end: a failed
/// run leaves nothing behind, nor does one stopped by a signal the `jem` binary handles ([`crate::cleanup`]), and
/// the temporary tree of a killed run on this machine is removed by the next run into the same `out`
/// (`sweep_stale`). Returns the degraded scene folders.
///
/// # Errors
/// [`Error::Output`] if `out` exists and is not an empty folder, or `out` and `src` contain one another,
/// [`Error::Dataset`] if `src` holds no scene; [`Error::Io`] / [`Error::Image`] naming the file for unreadable inputs
/// or failed writes.
pub fn degrade_tree(src: &Path, out: &Path, recipe: &Recipe, seed: u64) -> Result<Vec<PathBuf>> {
    let src_real = std::fs::canonicalize(src).map_err(|e| Error::io(src, e))?;
    if out.exists() {
        let empty = std::fs::read_dir(out).map_err(|e| Error::io(out, e))?.next().is_none();
        if !out.is_dir() || !empty {
            return Err(Error::output_at(out, "exists and is not an empty folder (refusing to write into it)"));
        }
    }
    let out_real = resolve_new_path(out)?;
    if out_real.starts_with(&src_real) || src_real.starts_with(&out_real) {
        return Err(Error::output_at(
            out,
            format!("the output folder must be outside the input {} (and not contain it)", src.display()),
        ));
    }
    let parent = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    crate::io::create_folder(&parent)?;
    let scenes = crate::dataset::walk::find_scenes(&[src.to_path_buf()])?;
    if scenes.is_empty() {
        return Err(Error::dataset_at(src, "no scene folder (with im0.png, im1.png, calib.txt) found"));
    }
    let prefix =
        format!(".{}.jem-tmp-{}-", out.file_name().unwrap_or_default().to_string_lossy(), crate::process::host_name());
    sweep_stale(&parent, &prefix);
    let tmp = parent.join(format!("{prefix}{}", std::process::id()));
    // A signal that stops the run removes the tree (crate::cleanup); the rename into place waits for it.
    crate::cleanup::hold().add_tree(&tmp);
    let result = (|| {
        std::fs::create_dir_all(&tmp).map_err(|e| Error::io(&tmp, e))?;
        let rels: Vec<PathBuf> = scenes
            .iter()
            .map(|s| match s.strip_prefix(src) {
                Ok(r) if !r.as_os_str().is_empty() => r.to_path_buf(),
                _ => PathBuf::from(crate::batch::scene_name(s)),
            })
            .collect();
        scenes
            .par_iter()
            .zip(&rels)
            .try_for_each(|(scene, rel)| degrade_scene(scene, &tmp.join(rel), rel, recipe, seed))?;
        let note = format!("recipe {recipe}\nseed {seed}\njem {}\n", env!("CARGO_PKG_VERSION"));
        crate::io::write_atomic(&tmp.join("degrade.txt"), note.as_bytes())?;
        let _held = crate::cleanup::hold();
        if out.exists() {
            std::fs::remove_dir(out).map_err(|e| Error::io(out, e))?;
        }
        std::fs::rename(&tmp, out).map_err(|e| Error::io(out, e))?;
        Ok(rels.iter().map(|r| out.join(r)).collect())
    })();
    let mut held = crate::cleanup::hold();
    if result.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    held.forget(&tmp);
    result
}

/// Removes the temporary trees `parent/PREFIX<pid>` that an earlier run on this machine left when it was killed
/// (SIGKILL, a power cut: it could not clean up): those whose process is gone (`/proc/<pid>` missing). Nothing is
/// removed where `/proc` cannot tell (no `/proc/self`).
pub(crate) fn sweep_stale(parent: &Path, prefix: &str) {
    if !crate::process::proc_available() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(parent) else { return };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = name.to_str().and_then(|n| n.strip_prefix(prefix)) else { continue };
        let alive = pid.parse::<u32>().map_or(true, |pid| crate::process::pid_exists(pid) != Some(false));
        if !alive && entry.file_type().is_ok_and(|t| t.is_dir()) {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

/// `path` made absolute through its deepest existing ancestor (links resolved), the missing components appended.
fn resolve_new_path(path: &Path) -> Result<PathBuf> {
    let mut existing = path.to_path_buf();
    let mut rest = Vec::new();
    while !existing.exists() {
        match (existing.parent(), existing.file_name()) {
            (Some(p), Some(name)) => {
                rest.push(name.to_os_string());
                existing = if p.as_os_str().is_empty() { PathBuf::from(".") } else { p.to_path_buf() };
            }
            _ => break,
        }
    }
    let mut real = std::fs::canonicalize(&existing).map_err(|e| Error::io(&existing, e))?;
    real.extend(rest.iter().rev());
    Ok(real)
}

/// One scene: both views degraded (noise streams from `seed` and the relative path), the other files copied.
fn degrade_scene(scene: &Path, dest: &Path, rel: &Path, recipe: &Recipe, seed: u64) -> Result<()> {
    std::fs::create_dir_all(dest).map_err(|e| Error::io(dest, e))?;
    // FNV-1a of the relative path: a per-scene stream that does not depend on where the tree lives.
    let key = crate::rng::fnv1a(crate::rng::FNV_OFFSET, rel.to_string_lossy().as_bytes());
    for (name, view) in [(LEFT_FILE, View::Left), (RIGHT_FILE, View::Right)] {
        let image = crate::io::png::load_rgb(&scene.join(name))?;
        let out = degrade(&image, recipe, view, seed ^ key)?;
        let mut rgb = Vec::with_capacity(out.len() * 3);
        for i in 0..out.len() {
            rgb.extend(out.rgb(i).map(|v| v as u8));
        }
        crate::io::png::write_rgb8_png(&dest.join(name), out.width, out.height, &rgb)?;
    }
    for name in COPIED_FILES {
        let from = scene.join(name);
        if from.is_file() {
            let bytes = crate::io::read_regular(&from)?;
            crate::io::write_atomic(&dest.join(name), &bytes)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth ramp image (no texture), so measured statistics are the degradation's.
    fn ramp(w: usize, h: usize) -> RgbImage {
        let mut img = RgbImage::new(w, h);
        for i in 0..w * h {
            let v = 40.0 + 150.0 * (i % w) as f32 / w as f32;
            for c in 0..3 {
                img.channels[c][i] = v.round();
            }
        }
        img
    }

    fn std_dev_of_difference(a: &RgbImage, b: &RgbImage) -> f64 {
        let d: Vec<f64> = a.channels[0].iter().zip(&b.channels[0]).map(|(x, y)| f64::from(x - y)).collect();
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt()
    }

    #[test]
    fn recipes_parse_print_and_refuse_nonsense() {
        let r: Recipe = "blur:1.5+noise:4+exposure:0.7:1.3+lowlight:0.2:1".parse().unwrap();
        assert_eq!(r.0.len(), 4);
        assert_eq!(r.to_string(), "blur:1.5+noise:4+exposure:0.7:1.3+lowlight:0.2:1");
        for bad in ["", "noise", "noise:", "noise:x", "noise:4:5", "lowlight:0:1", "lowlight:2:1", "noise:nan", "fog:1"]
        {
            assert!(bad.parse::<Recipe>().is_err(), "{bad:?} was accepted");
        }
        assert_eq!("jpeg:40".parse::<Recipe>().unwrap().to_string(), "jpeg:40");
        let none: Recipe = "none".parse().unwrap();
        assert_eq!((none.0.len(), none.to_string()), (0, "none".to_string()));
        let img = ramp(16, 8);
        assert_eq!(degrade(&img, &none, View::Right, 3).unwrap(), img, "none leaves the view as it is");
        assert!("none+noise:2".parse::<Recipe>().is_err(), "none is a whole recipe, not a step");
        assert_eq!("misalign:0.5:-0.2".parse::<Recipe>().unwrap().to_string(), "misalign:0.5:-0.2");
        for bad in ["misalign:1", "misalign:1:90", "misalign:200:0", "misalign:x:0"] {
            assert!(bad.parse::<Recipe>().is_err(), "{bad:?} was accepted");
        }
        for bad in ["jpeg:0", "jpeg:101", "jpeg:50.5", "jpeg"] {
            assert!(bad.parse::<Recipe>().is_err(), "{bad:?} was accepted");
        }
    }

    /// JPEG changes a textured image a little at high quality and more at low quality, deterministically.
    #[test]
    fn jpeg_loses_more_at_lower_quality() {
        let mut img = ramp(64, 48);
        for (i, v) in img.channels[1].iter_mut().enumerate() {
            *v = if (i / 3 + i / 64) % 2 == 0 { 40.0 } else { 200.0 };
        }
        let at = |q: &str| degrade(&img, &q.parse().unwrap(), View::Left, 1).unwrap();
        let (fine, coarse) = (std_dev_of_difference(&at("jpeg:95"), &img), std_dev_of_difference(&at("jpeg:10"), &img));
        assert!(fine > 0.0 && fine < coarse, "q95 {fine}, q10 {coarse}");
        assert_eq!(at("jpeg:10"), at("jpeg:10"));
    }

    /// Noise of σ 6 measures as about 6 (the rounding to 8 bits adds 1/12 of a grey level's variance), the two
    /// views get different noise, and the same seed gives the same image.
    #[test]
    fn noise_has_the_requested_sigma_and_is_seeded() {
        let img = ramp(200, 100);
        let r: Recipe = "noise:6".parse().unwrap();
        let left = degrade(&img, &r, View::Left, 7).unwrap();
        let sigma = std_dev_of_difference(&left, &img);
        assert!((sigma - 6.0).abs() < 0.2, "measured {sigma}");
        assert_eq!(left, degrade(&img, &r, View::Left, 7).unwrap());
        assert_ne!(left, degrade(&img, &r, View::Right, 7).unwrap());
        assert_ne!(left, degrade(&img, &r, View::Left, 8).unwrap());
    }

    /// Exposure changes the right view only, monotonically; low light darkens both to about the gain.
    #[test]
    fn exposure_is_right_only_and_low_light_darkens() {
        let img = ramp(64, 8);
        let r: Recipe = "exposure:0.5:1.5".parse().unwrap();
        assert_eq!(degrade(&img, &r, View::Left, 1).unwrap(), img);
        let right = degrade(&img, &r, View::Right, 1).unwrap();
        assert!(right.channels[1].windows(2).take(63).all(|p| p[0] <= p[1]), "not monotonic");
        let expected = 255.0 * (0.5f32 * 190.0 / 255.0).powf(1.5);
        assert!((right.channels[0][63] - expected).abs() <= 1.0);
        let dark = degrade(&img, &"lowlight:0.2:0".parse().unwrap(), View::Left, 1).unwrap();
        let mean = |im: &RgbImage| im.channels[0].iter().sum::<f32>() / im.len() as f32;
        assert!((mean(&dark) / mean(&img) - 0.2).abs() < 0.02, "{} vs {}", mean(&dark), mean(&img));
    }

    /// Misalignment moves the right view only: a whole-pixel shift moves the rows exactly, and a rotation about
    /// the centre keeps the centre pixel and moves the corners by about the angle × their distance.
    #[test]
    fn misalign_moves_the_right_view() {
        let mut img = RgbImage::new(41, 31);
        for (i, v) in img.channels[0].iter_mut().enumerate() {
            *v = ((i % 41) * 3 + (i / 41) * 2) as f32;
        }
        let r: Recipe = "misalign:2:0".parse().unwrap();
        assert_eq!(degrade(&img, &r, View::Left, 1).unwrap(), img);
        let moved = degrade(&img, &r, View::Right, 1).unwrap();
        for y in 2..31 {
            assert_eq!(moved.channels[0][y * 41..][..41], img.channels[0][(y - 2) * 41..][..41]);
        }
        let turned = degrade(&img, &"misalign:0:1".parse().unwrap(), View::Right, 1).unwrap();
        let centre = 15 * 41 + 20;
        assert_eq!(turned.channels[0][centre], img.channels[0][centre]);
        // The right edge's middle pixel samples 20·sin 1° ≈ 0.35 rows away: values change by about 2 × 0.35, rounded.
        let edge = 15 * 41 + 40;
        let moved_by = (turned.channels[0][edge] - img.channels[0][edge]).abs();
        assert!((0.5..=1.5).contains(&moved_by), "{moved_by}");
    }

    /// Blur keeps a constant image and the mean, and lowers the variance of noise.
    #[test]
    fn blur_smooths() {
        let img = ramp(80, 40);
        let noisy = degrade(&img, &"noise:10".parse().unwrap(), View::Left, 3).unwrap();
        let blurred = degrade(&noisy, &"blur:1.5".parse().unwrap(), View::Left, 3).unwrap();
        assert!(std_dev_of_difference(&blurred, &img) < 0.5 * std_dev_of_difference(&noisy, &img));
        let mut flat = RgbImage::new(9, 9);
        flat.channels.iter_mut().for_each(|c| c.fill(77.0));
        assert_eq!(degrade(&flat, &"blur:2".parse().unwrap(), View::Left, 0).unwrap(), flat);
    }
}
