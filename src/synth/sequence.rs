//! Synthetic stereo sequences with exact ground truth (`jem synth --frames N`): a scene of [`Scene::draw`] seen by
//! a camera that moves, or with an object that moves, or cut to another scene, frame by frame.
//!
//! # Motions ([`Motion`])
//! - `static`: the same pair every frame (with `noise_sigma` > 0, fresh sensor noise each frame);
//! - `pan`: the camera moves sideways along its baseline, 0.1 baseline per frame (at most 2 baselines over the
//!   sequence): a point of disparity d moves 0.1·d px per frame, near objects faster than the background, and
//!   new background comes into view behind them;
//! - `dolly`: the camera moves forward, a total of 0.2 of the nearest object's depth over the sequence: every
//!   disparity grows (d ↦ d / (1 − d·F)), the image expands about its centre. The scene is drawn in 80 % of the
//!   range so the last frame still fits it;
//! - `object`: a static camera and the frontmost object moving 2 px per frame towards the image centre (a
//!   disocclusion behind it, an occlusion ahead of it);
//! - `cut`: a static camera on the scene until frame ⌊N/2⌋, then on another scene (seed drawn from the first).
//!
//! # Rendering
//! Each frame is ray-cast like a single scene ([`super`]) through its pair of cameras ([`Camera`]): every sample
//! finds the nearest surface its ray meets ([`Scene::seen_by`]) and takes its texture at the point's reference
//! coordinates, so a surface keeps its pattern as the camera moves. The ground truth is the exact disparity of
//! the surface seen at the left pixel's centre in that frame's pair, the mask says whether the right camera sees
//! that point ([`Scene::seen_by_right_of`]). Frames are independent of each other: any frame renders alone, the
//! same bytes whatever the thread count.
//!
//! # Files ([`write_synth_sequence`])
//! The sequence layout of [`crate::sequence`]: `left/`, `right/`, `gt/<stem>.pfm`, `mask/<stem>.png`,
//! `calib.txt` (as a single scene's, `vmin`/`vmax` over all frames) and `truth.txt`: per frame the camera's
//! sideways position (baselines), its forward motion F, the scene shown (0, then 1 after a cut) and the moving
//! object's shift in px.

use std::str::FromStr;

use rayon::prelude::*;

use super::scene::{Camera, Scene};
use super::{MASK_NO_GT, MASK_OCCLUDED, MASK_VISIBLE, SynthParams, SynthScene};
use crate::degrade::{Degradation, Recipe, View};
use crate::error::{Error, Result};
use crate::image::{Plane, RgbImage};

/// How a synthetic sequence moves (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Motion {
    /// Nothing moves.
    Static,
    /// The camera moves sideways.
    Pan,
    /// The camera moves forward.
    Dolly,
    /// One object moves.
    Object,
    /// The scene changes half-way.
    Cut,
}

impl Motion {
    /// Every motion, in the order `--help` lists them.
    pub const ALL: [Motion; 5] = [Motion::Static, Motion::Pan, Motion::Dolly, Motion::Object, Motion::Cut];

    /// The name `--motion` takes.
    pub fn name(self) -> &'static str {
        match self {
            Motion::Static => "static",
            Motion::Pan => "pan",
            Motion::Dolly => "dolly",
            Motion::Object => "object",
            Motion::Cut => "cut",
        }
    }
}

impl FromStr for Motion {
    type Err = Error;
    fn from_str(s: &str) -> std::result::Result<Self, Error> {
        Motion::ALL.into_iter().find(|m| m.name() == s).ok_or_else(|| {
            Error::argument(format!("unknown motion {s:?} (expected static, pan, dolly, object or cut)"))
        })
    }
}

/// What sequence to render.
#[derive(Clone, Debug, PartialEq)]
pub struct SequenceParams {
    /// The scene (its seed draws it) and the image size and range.
    pub scene: SynthParams,
    /// Frames (2..=10000).
    pub frames: usize,
    /// How it moves.
    pub motion: Motion,
    /// Gaussian sensor noise, σ in grey levels, fresh in each frame and view (0: none).
    pub noise_sigma: f64,
    /// How the camera's exposure changes from frame to frame (none by default).
    pub gain: GainChange,
}

/// A camera's exposure from frame to frame: each frame's views (both alike, as one auto-exposure drives a rig)
/// are multiplied by a gain before the sensor noise is added, and rounded to 8 bits (clipped at 255). The ground
/// truth does not change.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GainChange {
    /// Each frame's gain is 1 + u·`jitter`, u uniform in [−1, 1) and drawn from the seed and the frame (0: none).
    pub jitter: f64,
    /// From frame `step_at` on, the gain is also × (1 + `step`) (an exposure step; 0: none).
    pub step: f64,
    /// See `step`.
    pub step_at: usize,
}

/// Mixed into the seed for the frames' gain jitter.
const GAIN_SEED_KEY: u64 = 0x6a1e_0e4f_05e0_0001;

impl GainChange {
    /// The gain of frame `k` of a sequence of seed `seed`.
    pub fn at(&self, seed: u64, k: usize) -> f64 {
        let stepped = if self.step != 0.0 && k >= self.step_at { 1.0 + self.step } else { 1.0 };
        let jitter = if self.jitter > 0.0 {
            let mut rng = crate::rng::SplitMix64::new(crate::rng::mix64(seed ^ GAIN_SEED_KEY) ^ k as u64);
            self.jitter * rng.range(-1.0, 1.0)
        } else {
            0.0
        };
        stepped * (1.0 + jitter)
    }

    fn validate(&self) -> Result<()> {
        if !(0.0..=0.5).contains(&self.jitter) {
            return Err(Error::param("gain jitter", self.jitter, "0..=0.5"));
        }
        if !(-0.5..=1.0).contains(&self.step) {
            return Err(Error::param("exposure step", self.step, "-0.5..=1"));
        }
        Ok(())
    }
}

/// Sideways camera motion per frame of a pan, in baselines.
const PAN_BASELINES_PER_FRAME: f64 = 0.1;
/// The most a pan moves the camera over a sequence, in baselines (longer sequences pan slower).
const PAN_MAX_BASELINES: f64 = 2.0;
/// A dolly's scene is drawn in this share of the range, which its disparities grow into.
const DOLLY_DRAW_SHARE: f64 = 0.8;
/// A dolly moves the camera forward by this share of the nearest possible object's depth over the sequence.
const DOLLY_DEPTH_SHARE: f64 = 0.2;
/// The largest disparity of a drawn scene, as a share of its range ([`Scene::draw`]).
const DRAWN_MAX_SHARE: f64 = 0.92;
/// How fast the moving object moves, px per frame.
const OBJECT_PX_PER_FRAME: f64 = 2.0;
/// Mixed into the seed for the scene after a cut.
const CUT_SEED_KEY: u64 = 0x0c07_5ce4_e000_0001;

impl SequenceParams {
    /// Checks the values.
    ///
    /// # Errors
    /// [`Error::InvalidParam`] naming the first value out of range.
    pub fn validate(&self) -> Result<()> {
        self.scene.validate()?;
        if !(2..=10_000).contains(&self.frames) {
            return Err(Error::param("frames", self.frames, "2..=10000"));
        }
        if !(0.0..=100.0).contains(&self.noise_sigma) {
            return Err(Error::param("noise", self.noise_sigma, "0..=100 grey levels"));
        }
        self.gain.validate()
    }

    /// The camera of frame `k`.
    fn camera(&self, k: usize) -> Camera {
        let p = &self.scene;
        let (cx, cy) = ((p.width as f64 - 1.0) / 2.0, (p.height as f64 - 1.0) / 2.0);
        let t = k as f64;
        let last = (self.frames - 1) as f64;
        let (x_baselines, forward) = match self.motion {
            Motion::Pan => (t * PAN_BASELINES_PER_FRAME.min(PAN_MAX_BASELINES / last), 0.0),
            Motion::Dolly => {
                let nearest = DRAWN_MAX_SHARE * self.draw_params().ndisp as f64;
                (0.0, t / last * DOLLY_DEPTH_SHARE / nearest)
            }
            _ => (0.0, 0.0),
        };
        Camera { x_baselines, forward, cx, cy }
    }

    /// The parameters the scene is drawn with (a dolly's in a smaller range).
    fn draw_params(&self) -> SynthParams {
        let ndisp = match self.motion {
            Motion::Dolly => (DOLLY_DRAW_SHARE * self.scene.ndisp as f64).round() as usize,
            _ => self.scene.ndisp,
        };
        SynthParams { ndisp, ..self.scene.clone() }
    }

    /// The scene frame `k` shows, and what moved in it.
    fn scene_at(&self, k: usize) -> (Scene, FrameTruth) {
        let cut = self.motion == Motion::Cut && k >= self.frames / 2;
        let mut draw = self.draw_params();
        if cut {
            draw.seed = crate::rng::mix64(draw.seed ^ CUT_SEED_KEY);
        }
        let mut scene = Scene::draw(&draw);
        let camera = self.camera(k);
        let mut shift = [0.0; 2];
        if self.motion == Motion::Object {
            shift = scene.move_front_object(k as f64 * OBJECT_PX_PER_FRAME, [camera.cx, camera.cy]);
        }
        let truth = FrameTruth {
            gain: self.gain.at(self.scene.seed, k),
            camera_x_baselines: camera.x_baselines,
            forward: camera.forward,
            scene: usize::from(cut),
            object_shift_px: shift,
        };
        (scene, truth)
    }
}

/// What a frame shows: where its camera is, what moved and its exposure (the lines of `truth.txt`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameTruth {
    /// The gain the frame's views were multiplied by ([`GainChange`]).
    pub gain: f64,
    /// The camera's sideways position, in baselines.
    pub camera_x_baselines: f64,
    /// Its forward motion F (a disparity d of the first frame is d / (1 − d·F) here).
    pub forward: f64,
    /// The scene shown: 0, then 1 after a cut.
    pub scene: usize,
    /// How far the moving object has moved, px.
    pub object_shift_px: [f64; 2],
}

impl Scene {
    /// Moves the frontmost object `distance` px towards `towards` (straight right when it is there already),
    /// carrying its plane and texture along. Returns the shift.
    fn move_front_object(&mut self, distance: f64, towards: [f64; 2]) -> [f64; 2] {
        let Some(s) = self.surfaces.last_mut() else { return [0.0; 2] };
        let Some([x, y]) = s.shape.centre() else { return [0.0; 2] };
        let (dx, dy) = (towards[0] - x, towards[1] - y);
        let len = dx.hypot(dy);
        let (ux, uy) = if len > 1.0 { (dx / len, dy / len) } else { (1.0, 0.0) };
        let shift = [distance * ux, distance * uy];
        s.shape = s.shape.translated(shift[0], shift[1]);
        s.c -= s.a * shift[0] + s.b * shift[1];
        s.texture.offset = shift;
        shift
    }
}

/// Renders frame `k` of the sequence: its pair, ground truth and mask (`vmin`/`vmax` of this frame's ground
/// truth), and what it shows.
///
/// # Errors
/// [`Error::InvalidParam`] if `params` does not validate or `k` is not a frame of it.
pub fn render_frame(params: &SequenceParams, k: usize) -> Result<(SynthScene, FrameTruth)> {
    params.validate()?;
    if k >= params.frames {
        return Err(Error::param("frame", k, format!("0..{}", params.frames)));
    }
    let (scene, truth) = params.scene_at(k);
    let cam = params.camera(k);
    let (w, h) = (params.scene.width, params.scene.height);
    let (mut left, mut right) = (render_view(&scene, &cam, w, h), render_view(&scene, &cam.right(), w, h));
    let gain = params.gain.at(params.scene.seed, k);
    if gain != 1.0 {
        for ch in left.channels.iter_mut().chain(right.channels.iter_mut()) {
            ch.iter_mut().for_each(|v| *v = (*v * gain as f32).round().clamp(0.0, 255.0));
        }
    }
    if params.noise_sigma > 0.0 {
        let recipe = Recipe(vec![Degradation::Noise { sigma: params.noise_sigma }]);
        let seed = crate::sequence::frame_seed(params.scene.seed, k);
        left = crate::degrade::degrade(&left, &recipe, View::Left, seed)?;
        right = crate::degrade::degrade(&right, &recipe, View::Right, seed)?;
    }
    let mut gt = Plane::new(w, h, f32::INFINITY);
    let mut mask = Plane::new(w, h, MASK_NO_GT);
    gt.data.par_chunks_mut(w).zip(mask.data.par_chunks_mut(w)).enumerate().for_each(|(y, (gt_row, mask_row))| {
        for (x, (g, m)) in gt_row.iter_mut().zip(mask_row.iter_mut()).enumerate() {
            if let Some((s, d, _, _)) = scene.seen_by(&cam, x as f64, y as f64) {
                *g = d as f32;
                let seen = scene.seen_by_right_of(&cam, s, x as f64, y as f64, d);
                *m = if seen { MASK_VISIBLE } else { MASK_OCCLUDED };
            }
        }
    });
    let (lo, hi) = gt
        .data
        .iter()
        .filter(|d| d.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &d| (lo.min(d), hi.max(d)));
    let ndisp = params.scene.ndisp;
    Ok((SynthScene { left, right, gt, mask, ndisp, vmin: lo.floor(), vmax: hi.ceil() }, truth))
}

/// One view through `cam`: 2×2 samples per pixel, each the texture of the surface its ray meets (black where
/// none is in front of the camera), averaged and rounded to 8 bits.
fn render_view(scene: &Scene, cam: &Camera, w: usize, h: usize) -> RgbImage {
    const OFFSETS: [f64; 2] = [-0.25, 0.25];
    let mut rgb = vec![[0u8; 3]; w * h];
    rgb.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, px) in row.iter_mut().enumerate() {
            let mut sum = [0.0f64; 3];
            for dy in OFFSETS {
                for dx in OFFSETS {
                    if let Some((s, _, x0, y0)) = scene.seen_by(cam, x as f64 + dx, y as f64 + dy) {
                        let c = scene.surfaces[s].texture.colour(x0, y0);
                        sum.iter_mut().zip(c).for_each(|(acc, v)| *acc += v);
                    }
                }
            }
            *px = sum.map(|v| (v / 4.0).round().clamp(0.0, 255.0) as u8);
        }
    });
    let mut out = RgbImage::new(w, h);
    for (i, px) in rgb.iter().enumerate() {
        for (channel, &v) in out.channels.iter_mut().zip(px) {
            channel[i] = f32::from(v);
        }
    }
    out
}

/// Renders the sequence and writes it into `out` ([`crate::sequence::write_sequence`]: one frame in memory at a
/// time, all or none, refused where a scene or sequence is already). Returns the stems written.
///
/// # Errors
/// [`Error::InvalidParam`] if `params` does not validate; as [`crate::sequence::write_sequence`].
pub fn write_synth_sequence(out: &std::path::Path, params: &SequenceParams) -> Result<Vec<String>> {
    params.validate()?;
    let range = std::cell::Cell::new((f32::INFINITY, f32::NEG_INFINITY));
    let truth = std::cell::RefCell::new(format!(
        "# jem synth --frames {} --motion {} --seed {} --noise {} --gain-jitter {} --exposure-step {}:{}\n# frame \
         camera_x_baselines forward scene object_dx_px object_dy_px gain\n",
        params.frames,
        params.motion.name(),
        params.scene.seed,
        params.noise_sigma,
        params.gain.jitter * 100.0,
        params.gain.step_at,
        params.gain.step * 100.0
    ));
    let mut frame = |k: usize| {
        let (s, t) = render_frame(params, k)?;
        let (lo, hi) = range.get();
        range.set((lo.min(s.vmin), hi.max(s.vmax)));
        truth.borrow_mut().push_str(&format!(
            "{} {:.6} {:.9} {} {:.3} {:.3} {:.6}\n",
            crate::sequence::frame_stem(k),
            t.camera_x_baselines,
            t.forward,
            t.scene,
            t.object_shift_px[0],
            t.object_shift_px[1],
            t.gain
        ));
        Ok(crate::sequence::SequenceFrame { left: s.left, right: s.right, gt: Some(s.gt), mask: Some(s.mask) })
    };
    let (w, h, ndisp) = (params.scene.width, params.scene.height, params.scene.ndisp);
    let stems = crate::sequence::write_sequence(out, params.frames, &mut frame, &mut || {
        let (vmin, vmax) = range.get();
        vec![
            (crate::dataset::CALIB_FILE, super::calib_text(w, h, ndisp, vmin, vmax)),
            ("truth.txt", truth.borrow().clone()),
        ]
    })?;
    Ok(stems)
}

#[cfg(test)]
#[path = "sequence_tests.rs"]
mod tests;
