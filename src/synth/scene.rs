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
