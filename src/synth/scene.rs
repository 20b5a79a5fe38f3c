//! The scene model: planar surfaces (a background everywhere, objects in their own depth bands) with shapes and
//! textures, drawn from a seed ([`Scene::draw`]), and which surface a ray of either view meets.

use super::SynthParams;
use super::texture::Texture;
use crate::rng::SplitMix64;

/// The scene: surfaces in drawing order (index 0 is the background, which covers everything).
#[derive(Clone, Debug)]
pub(super) struct Scene {
    pub(super) surfaces: Vec<Surface>,
}

/// A planar surface: disparity `a·x + b·y + c` in left-view coordinates, restricted to `shape`.
#[derive(Clone, Debug)]
pub(super) struct Surface {
    pub(super) shape: Shape,
    pub(super) a: f64,
    pub(super) b: f64,
    pub(super) c: f64,
    pub(super) texture: Texture,
}

/// Where a surface exists, in left-view coordinates.
#[derive(Clone, Debug)]
pub(super) enum Shape {
    Everywhere,
    Rect {
        x0: f64,
        y0: f64,
        x1: f64,
        y1: f64,
    },
    Disc {
        cx: f64,
        cy: f64,
        r: f64,
    },
    /// A simple (star-shaped) polygon; inside by the even-odd rule.
    Polygon(Vec<[f64; 2]>),
}

impl Shape {
    pub(super) fn covers(&self, x: f64, y: f64) -> bool {
        match self {
            Shape::Everywhere => true,
            Shape::Rect { x0, y0, x1, y1 } => (*x0..*x1).contains(&x) && (*y0..*y1).contains(&y),
            Shape::Disc { cx, cy, r } => (x - cx).powi(2) + (y - cy).powi(2) < r * r,
            Shape::Polygon(v) => {
                let mut inside = false;
                for (i, p) in v.iter().enumerate() {
                    let q = v[(i + 1) % v.len()];
                    if (p[1] > y) != (q[1] > y) && x < p[0] + (y - p[1]) / (q[1] - p[1]) * (q[0] - p[0]) {
                        inside = !inside;
                    }
                }
                inside
            }
        }
    }
}

impl Shape {
    /// The shape moved by `(dx, dy)`.
    pub(super) fn translated(&self, dx: f64, dy: f64) -> Shape {
        match self {
            Shape::Everywhere => Shape::Everywhere,
            Shape::Rect { x0, y0, x1, y1 } => Shape::Rect { x0: x0 + dx, y0: y0 + dy, x1: x1 + dx, y1: y1 + dy },
            Shape::Disc { cx, cy, r } => Shape::Disc { cx: cx + dx, cy: cy + dy, r: *r },
            Shape::Polygon(v) => Shape::Polygon(v.iter().map(|p| [p[0] + dx, p[1] + dy]).collect()),
        }
    }

    /// A point inside the shape's bounds: the centre of a rectangle or disc, the mean vertex of a polygon (`None`
    /// for the background).
    pub(super) fn centre(&self) -> Option<[f64; 2]> {
        match self {
            Shape::Everywhere => None,
            Shape::Rect { x0, y0, x1, y1 } => Some([0.5 * (x0 + x1), 0.5 * (y0 + y1)]),
            Shape::Disc { cx, cy, .. } => Some([*cx, *cy]),
            Shape::Polygon(v) => {
                let n = v.len().max(1) as f64;
                Some([v.iter().map(|p| p[0]).sum::<f64>() / n, v.iter().map(|p| p[1]).sum::<f64>() / n])
            }
        }
    }
}

/// A camera of a sequence's frame, relative to the reference left camera (the one [`Scene::visible_left`] looks
/// through): moved `x_baselines` baselines along the baseline and forward along the optical axis by `forward` ×
/// f·B (a point of disparity d at the reference camera has disparity d / (1 − d·forward) here), principal point
/// `(cx, cy)`. Its right camera is one baseline further along.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Camera {
    pub(super) x_baselines: f64,
    pub(super) forward: f64,
    pub(super) cx: f64,
    pub(super) cy: f64,
}

impl Camera {
    /// The right camera of the pair this camera is the left one of.
    pub(super) fn right(&self) -> Camera {
        Camera { x_baselines: self.x_baselines + 1.0, ..*self }
    }
}

impl Surface {
    /// Where the ray of `cam` through its image point `(x, y)` meets the surface's plane: the disparity there in
    /// `cam`'s pair and the point's reference coordinates; `None` when it meets it behind the camera or not at all.
    ///
    /// A reference point `(x₀, y₀)` of disparity d is seen by `cam` at `x − cx = (x₀ − cx − X·d) / (1 − d·F)`,
    /// `y − cy = (y₀ − cy) / (1 − d·F)` (X = `x_baselines`, F = `forward`), with disparity `d / (1 − d·F)`;
    /// on the plane `d = a·x₀ + b·y₀ + c` that solves to `d = (a·x + b·y + c) / (1 − a·X + F·(a·(x − cx) + b·(y −
    /// cy)))`.
    pub(super) fn meet(&self, cam: &Camera, x: f64, y: f64) -> Option<(f64, f64, f64)> {
        let (u, v) = (x - cam.cx, y - cam.cy);
        let den = 1.0 - self.a * cam.x_baselines + cam.forward * (self.a * u + self.b * v);
        let d = (self.a * x + self.b * y + self.c) / den;
        let depth = 1.0 - d * cam.forward;
        if !(den > 0.0 && d > 0.0 && depth > 0.0) {
            return None;
        }
        Some((d / depth, cam.cx + u * depth + cam.x_baselines * d, cam.cy + v * depth))
    }
}

impl Surface {
    #[inline]
    pub(super) fn disparity(&self, x: f64, y: f64) -> f64 {
        self.a * x + self.b * y + self.c
    }

    /// The left coordinate `x_l` whose right-view image is `x_r`: `x_l − (a·x_l + b·y + c) = x_r`.
    #[inline]
    pub(super) fn left_x_of_right(&self, xr: f64, y: f64) -> f64 {
        (xr + self.b * y + self.c) / (1.0 - self.a)
    }
}

impl Scene {
    /// The surface seen at left-view point `(x, y)` and its disparity.
    pub(super) fn visible_left(&self, x: f64, y: f64) -> (usize, f64) {
        let mut best = (0, self.surfaces[0].disparity(x, y));
        for (i, s) in self.surfaces.iter().enumerate().skip(1) {
            let d = s.disparity(x, y);
            if d > best.1 && s.shape.covers(x, y) {
                best = (i, d);
            }
        }
        best
    }

    /// The surface seen at right-view point `(x_r, y)`, its disparity and the left coordinate of that point.
    pub(super) fn visible_right(&self, xr: f64, y: f64) -> (usize, f64, f64) {
        let xl0 = self.surfaces[0].left_x_of_right(xr, y);
        let mut best = (0, xl0 - xr, xl0);
        for (i, s) in self.surfaces.iter().enumerate().skip(1) {
            let xl = s.left_x_of_right(xr, y);
            if xl - xr > best.1 && s.shape.covers(xl, y) {
                best = (i, xl - xr, xl);
            }
        }
        best
    }

    /// True when the point of surface `s` at left `(x, y)`, disparity `d`, is seen by the right camera: its match
    /// `x − d` is in the image (≥ 0) and no other surface is in front of it along that right ray.
    pub(super) fn seen_from_right(&self, s: usize, x: f64, y: f64, d: f64) -> bool {
        let xr = x - d;
        xr >= 0.0
            && self.surfaces.iter().enumerate().all(|(i, t)| {
                if i == s {
                    return true;
                }
                let xl = t.left_x_of_right(xr, y);
                !(xl - xr > d && t.shape.covers(xl, y))
            })
    }

    /// The surface `cam` sees at its image point `(x, y)`: its index, the disparity there in `cam`'s pair and the
    /// point's reference coordinates (the nearest surface whose shape covers the point); `None` where no surface
    /// is in front of the camera.
    pub(super) fn seen_by(&self, cam: &Camera, x: f64, y: f64) -> Option<(usize, f64, f64, f64)> {
        let mut best: Option<(usize, f64, f64, f64)> = None;
        for (i, s) in self.surfaces.iter().enumerate() {
            if let Some((d, x0, y0)) = s.meet(cam, x, y)
                && best.is_none_or(|b| d > b.1)
                && s.shape.covers(x0, y0)
            {
                best = Some((i, d, x0, y0));
            }
        }
        best
    }

    /// [`Scene::seen_from_right`] for the pair of `cam`: the point of surface `s` that `cam` sees at `(x, y)` with
    /// disparity `d` has its match `x − d` in the image and no other surface in front of it on the right ray.
    pub(super) fn seen_by_right_of(&self, cam: &Camera, s: usize, x: f64, y: f64, d: f64) -> bool {
        let (right, xr) = (cam.right(), x - d);
        xr >= 0.0
            && self.surfaces.iter().enumerate().all(|(i, t)| {
                i == s || !matches!(t.meet(&right, xr, y), Some((dt, x0, y0)) if dt > d && t.shape.covers(x0, y0))
            })
    }

    /// Draws a scene from the seed: the background in 6–26 % of ndisp, the objects in 32–92 %, one band each.
    pub(super) fn draw(p: &SynthParams) -> Scene {
        let mut rng = SplitMix64::new(p.seed);
        let (w, h, n) = (p.width as f64, p.height as f64, p.ndisp as f64);
        let mut surfaces = Vec::new();

        // Background: centre disparity 0.16·n, varying by at most ±0.1·n over the image.
        let (a, b) = slopes(&mut rng, 0.1 * n, (w - 1.0) / 2.0, (h - 1.0) / 2.0);
        let c = 0.16 * n - a * (w - 1.0) / 2.0 - b * (h - 1.0) / 2.0;
        surfaces.push(Surface { shape: Shape::Everywhere, a, b, c, texture: Texture::draw(&mut rng) });

        let count = 3 + rng.below_by_remainder(4);
        let (lo, hi) = (0.32 * n, 0.92 * n);
        let band = (hi - lo) / count as f64;
        for k in 0..count {
            let (rx, ry) = (rng.range(0.1, 0.22) * w, rng.range(0.15, 0.32) * h);
            let (cx, cy) = (rng.range(0.1, 0.9) * w, rng.range(0.1, 0.9) * h);
            let shape = match rng.below_by_remainder(3) {
                0 => Shape::Rect { x0: cx - rx, y0: cy - ry, x1: cx + rx, y1: cy + ry },
                1 => Shape::Disc { cx, cy, r: rx.min(ry) },
                _ => {
                    let corners = 3 + rng.below_by_remainder(5);
                    let turn = rng.range(0.0, std::f64::consts::TAU);
                    let vertices = (0..corners)
                        .map(|i| {
                            let angle =
                                turn + (i as f64 + rng.range(-0.3, 0.3)) * std::f64::consts::TAU / corners as f64;
                            let radius = rng.range(0.7, 1.0);
                            [cx + radius * rx * angle.cos(), cy + radius * ry * angle.sin()]
                        })
                        .collect();
                    Shape::Polygon(vertices)
                }
            };
            // The shape lies in the box cx ± rx, cy ± ry, so its disparity stays within ±0.35·band of the band's
            // middle: bands never overlap and the objects never intersect.
            let mid = lo + (k as f64 + 0.5) * band;
            let (a, b) = slopes(&mut rng, 0.35 * band, rx, ry);
            let c = mid - a * cx - b * cy;
            surfaces.push(Surface { shape, a, b, c, texture: Texture::draw(&mut rng) });
        }
        Scene { surfaces }
    }
}

/// Random slopes `(a, b)` with `|a|·rx + |b|·ry ≤ budget` (and `|a| ≤ 0.5`, so `1 − a` stays well away from 0).
fn slopes(rng: &mut SplitMix64, budget: f64, rx: f64, ry: f64) -> (f64, f64) {
    let share = rng.range(0.2, 0.8);
    let scale = rng.range(0.5, 1.0);
    let sign = |rng: &mut SplitMix64| if rng.below_by_remainder(2) == 0 { -1.0 } else { 1.0 };
    let a = (sign(rng) * scale * share * budget / rx).clamp(-0.5, 0.5);
    let b = sign(rng) * scale * (1.0 - share) * budget / ry;
    (a, b)
}
