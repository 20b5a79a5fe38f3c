//! Inference on every `step`-th disparity, the full labels recovered from the cost (a large image's fine pass).
//!
//! A label is one pixel of disparity, so an image k times larger in side has k times as many labels over the same
//! scene, and the inference's work (pixels × labels) grows as k³. The mean field decides which surface a pixel is
//! on; that decision needs the precision the parameters were tuned at, not the finer one the larger image's
//! labels offer. So above [`crate::params::MeanFieldParams::reference_px`] the inference runs on labels grouped
//! `step` at a time (`step` = k rounded), each group's cost the lowest of its members' (a minimum between two
//! labels is not lost between groups), and each view's decoded disparity is brought back to the full labels by
//! the cost around it: the lowest of the three labels nearest the group's position, with the cost's parabola
//! through it ([`refine_from_full`]). The right view's groups and refinement read the left view's volume
//! (C_R(x, d) = C_L(x + d, d)), so only one full volume is ever built.

use rayon::prelude::*;

use crate::image::{CostVolume, DisparityMap};

/// Which view a grouped volume or a refinement is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum View {
    Left,
    Right,
}

/// The left view's full volume `full` read as `view`'s: C_R(x, d) = C_L(x + d, d), `out_of_view` past the edge.
#[derive(Clone, Copy)]
struct FullCost<'a> {
    full: &'a CostVolume,
    view: View,
    out_of_view: f32,
}

impl FullCost<'_> {
    /// The cost of label `d` at column `x` of row `row` (the full volume's row `y`, `width × M` values).
    #[inline]
    fn at(&self, row: &[f32], x: usize, d: usize) -> f32 {
        let m = self.full.ndisp;
        match self.view {
            View::Left => row[x * m + d],
            View::Right if x + d < self.full.width => row[(x + d) * m + d],
            View::Right => self.out_of_view,
        }
    }
}

/// `view`'s volume on labels grouped `step` at a time (group g: labels g·step … g·step + step − 1, the last one
/// shorter), each group's cost the lowest of its members', from the left view's full volume `full` (the right
/// view's costs past the image's edge are `out_of_view`), written into `storage` (any contents).
pub(crate) fn grouped_volume(
    full: &CostVolume,
    view: View,
    step: usize,
    out_of_view: f32,
    storage: Vec<f32>,
) -> CostVolume {
    let (w, h, m, step) = (full.width, full.height, full.ndisp, step.max(1));
    let groups = m.div_ceil(step);
    let mut data = crate::image::reuse_storage(storage, w * h * groups); // every entry is written below
    data.par_chunks_mut(w * groups).enumerate().for_each(|(y, out)| {
        let row = &full.data[y * w * m..][..w * m];
        match view {
            View::Left => match step {
                2 => group_left_row::<2>(row, m, out),
                3 => group_left_row::<3>(row, m, out),
                4 => group_left_row::<4>(row, m, out),
                _ => {
                    for (out, costs) in out.chunks_exact_mut(groups).zip(row.chunks_exact(m)) {
                        for (o, members) in out.iter_mut().zip(costs.chunks(step)) {
                            *o = lowest(members);
                        }
                    }
                }
            },
            View::Right => group_right_row(row, m, step, out_of_view, out),
        }
    });
    CostVolume { width: w, height: h, ndisp: groups, data }
}

/// One row of the right view's grouped volume from the left view's full row `row` (`m` labels): C_R(x, d) =
/// C_L(x + d, d), `out_of_view` where x + d is past the edge. The left row is read in order and each value taken
/// into its right pixel's group (the minimum is exact in any order), which reads memory in sequence where the
/// right view's own order would jump m + 1 values per label.
fn group_right_row(row: &[f32], m: usize, step: usize, out_of_view: f32, out: &mut [f32]) {
    let w = row.len() / m;
    let groups = m.div_ceil(step);
    // A group with a member past the edge holds that member's cost at most.
    for (x, out) in out.chunks_exact_mut(groups).enumerate() {
        for (g, o) in out.iter_mut().enumerate() {
            let last = ((g + 1) * step).min(m) - 1;
            *o = if x + last >= w { out_of_view } else { f32::INFINITY };
        }
    }
    for (xl, costs) in row.chunks_exact(m).enumerate() {
        // Label d = g·step + j goes to right pixel xl − d, group g (d ≤ xl).
        for (g, members) in costs[..(xl + 1).min(m)].chunks(step).enumerate() {
            for (j, &c) in members.iter().enumerate() {
                let o = &mut out[(xl - g * step - j) * groups + g];
                *o = o.min(c);
            }
        }
    }
}

/// The lowest of `members` (∞ for none).
#[inline(always)]
fn lowest(members: &[f32]) -> f32 {
    members.iter().copied().fold(f32::INFINITY, f32::min)
}

/// One row of the left view's grouped volume, `STEP` labels a group (a constant, so that the groups of a pixel are
/// taken as whole vectors): each pixel's `m` costs of `row` into its `m.div_ceil(STEP)` groups of `out`.
fn group_left_row<const STEP: usize>(row: &[f32], m: usize, out: &mut [f32]) {
    let (whole, groups) = (m / STEP, m.div_ceil(STEP));
    for (out, costs) in out.chunks_exact_mut(groups).zip(row.chunks_exact(m)) {
        let (head, tail) = costs.split_at(whole * STEP);
        let (out_head, out_tail) = out.split_at_mut(whole);
        for (o, members) in out_head.iter_mut().zip(head.chunks_exact(STEP)) {
            *o = members[1..].iter().fold(members[0], |a, &b| a.min(b));
        }
        if let Some(o) = out_tail.first_mut() {
            *o = lowest(tail);
        }
    }
}

/// Brings `view`'s map `disp`, decoded on labels grouped `step` at a time, back to the full labels of `full` (the
/// left view's full volume; `out_of_view` past the right view's edge): a group position g (fractional, from the
/// decode's parabola) stands for the label c = g·step + (step − 1)/2; the pixel takes the lowest-cost label of
/// c − 1, c, c + 1 (c rounded, within the range) and the vertex of the cost's parabola through it (at most ½ label
/// away, none at the range's ends or where the cost is not convex there). Invalid pixels stay as they are.
pub(crate) fn refine_from_full(disp: &mut DisparityMap, full: &CostVolume, view: View, step: usize, out_of_view: f32) {
    let (w, m) = (full.width, full.ndisp);
    let cost = FullCost { full, view, out_of_view };
    let (k, top) = (step as f32, (m - 1) as f32);
    disp.data.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
        let row = &full.data[y * w * m..][..w * m];
        for (x, d) in out.iter_mut().enumerate().filter(|(_, d)| d.is_finite()) {
            let centre = (*d * k + (k - 1.0) / 2.0).round().clamp(0.0, top) as usize;
            let candidates = centre.saturating_sub(1)..=(centre + 1).min(m - 1);
            let best = candidates.min_by(|&a, &b| cost.at(row, x, a).total_cmp(&cost.at(row, x, b))).unwrap_or(centre);
            *d = best as f32;
            if best > 0 && best + 1 < m {
                let (a, b, c) = (cost.at(row, x, best - 1), cost.at(row, x, best), cost.at(row, x, best + 1));
                let curvature = a - 2.0 * b + c;
                if curvature > 1e-6 {
                    *d += (0.5 * (a - c) / curvature).clamp(-0.5, 0.5);
                }
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cost::derive_right_volume;
    use crate::image::Plane;
    use crate::test_util::rand_vec;

    /// The whole pipeline on a synthetic scene with the reference size lowered so that its labels are grouped two at
    /// a time: the grouped path runs (its stages are timed), and its answer is about as accurate as every label's,
    /// with the local term alone there (the default) and with both terms.
    #[test]
    fn a_scene_matched_on_grouped_labels_is_as_accurate() {
        let scene =
            crate::synth::render_scene(&crate::synth::SynthParams { width: 240, height: 160, ndisp: 40, seed: 11 })
                .unwrap();
        let pair = crate::image::StereoPair::borrowed(&scene.left, &scene.right, scene.ndisp).unwrap();
        let run_with = |reference_px: f32, grouped_local: bool| {
            let mut params = crate::params::Params::default();
            params.meanfield.reference_px = reference_px;
            params.meanfield.grouped_local = grouped_local;
            crate::pipeline::run(&params, &pair).unwrap()
        };
        let run = |reference_px: f32| run_with(reference_px, true);
        let error = |out: &crate::pipeline::PipelineOutput| {
            let visible = scene.mask.data.iter().map(|&m| m == crate::synth::MASK_VISIBLE);
            let pairs = out.disparity.data.iter().zip(&scene.gt.data).zip(visible).filter(|(_, v)| *v);
            let (sum, n) = pairs.fold((0.0f64, 0usize), |(s, n), ((d, g), _)| (s + f64::from((d - g).abs()), n + 1));
            sum / n as f64
        };
        let staged = |out: &crate::pipeline::PipelineOutput, name| out.timings.stages.iter().any(|(n, _)| *n == name);
        let (every, grouped) = (run(0.0), run(10_000.0)); // 38 400 pixels: k = 1.96, groups of 2
        assert!(!staged(&every, "group labels") && staged(&grouped, "group labels"));
        let (e, g) = (error(&every), error(&grouped));
        assert!(e < 0.5, "every label: mean error {e}");
        assert!(g < 1.15 * e + 0.02, "grouped labels: mean error {g} against {e}");
        // Both terms on the groups: a different answer, as accurate.
        let both = run_with(10_000.0, false);
        assert_ne!(both.disparity.data, grouped.disparity.data);
        let b = error(&both);
        assert!(b < 1.15 * e + 0.02, "grouped labels, both terms: mean error {b} against {e}");
    }

    fn random_volume(w: usize, h: usize, m: usize, seed: u64) -> CostVolume {
        CostVolume { width: w, height: h, ndisp: m, data: rand_vec(w * h * m, seed) }
    }

    /// Each group holds the lowest of its labels' costs, the right view's read through the derived right volume.
    #[test]
    fn a_group_holds_its_lowest_label() {
        let (w, h, oov) = (9, 4, 5.0);
        for (m, step) in [7, 8].into_iter().flat_map(|m| (1..=5).map(move |step| (m, step))) {
            let full = random_volume(w, h, m, 3);
            let right = derive_right_volume(&full, oov);
            for (view, reference) in [(View::Left, &full), (View::Right, &right)] {
                let grouped = grouped_volume(&full, view, step, oov, Vec::new());
                assert_eq!(grouped.ndisp, m.div_ceil(step));
                for i in 0..w * h {
                    for (g, &c) in grouped.pixel(i).iter().enumerate() {
                        let members = &reference.pixel(i)[g * step..((g + 1) * step).min(m)];
                        let lowest = members.iter().copied().fold(f32::INFINITY, f32::min);
                        assert_eq!(
                            c.to_bits(),
                            lowest.to_bits(),
                            "{view:?} {m} labels, step {step}, pixel {i} group {g}"
                        );
                    }
                }
            }
        }
    }

    /// A cost that is a parabola in the label with its vertex at a known disparity: the refinement finds the vertex
    /// from the group's position, for both views.
    #[test]
    fn the_refinement_finds_the_costs_vertex() {
        let (w, h, m, step) = (40, 3, 40, 2);
        let truth = |x: usize, y: usize| 6.3 + 0.4 * x as f32 + 0.5 * y as f32;
        let mut full = CostVolume::new(w, h, m, 0.0);
        for y in 0..h {
            for x in 0..w {
                let t = truth(x, y);
                for d in 0..m {
                    full.data[(y * w + x) * m + d] = (d as f32 - t).powi(2);
                }
            }
        }
        // The group positions a decode would give: the true disparity in group units, off by up to a group.
        let mut left = Plane::new(w, h, 0.0f32);
        for (i, d) in left.data.iter_mut().enumerate() {
            let t = truth(i % w, i / w);
            *d = ((t - 0.5) / step as f32).round() + if i % 2 == 0 { 0.3 } else { -0.3 };
        }
        refine_from_full(&mut left, &full, View::Left, step, 1e3);
        for (i, d) in left.data.iter().enumerate() {
            assert!((d - truth(i % w, i / w)).abs() < 1e-3, "pixel {i}: {d}");
        }
        // The right view's pixel x sees the left view's x + d: the cost (d − truth(x + d, y))² is a parabola in d
        // with its vertex where d = truth(x + d, y). Pixels whose labels near it fall past the edge stay invalid.
        let vertex = |x: usize, y: usize| (6.3 + 0.4 * x as f32 + 0.5 * y as f32) / 0.6;
        let inside = |x: usize, y: usize| x as f32 + vertex(x, y) + 3.0 < w as f32;
        let mut right = Plane::new(w, h, f32::INFINITY);
        for (i, d) in right.data.iter_mut().enumerate().filter(|(i, _)| inside(i % w, i / w)) {
            *d = (vertex(i % w, i / w) - 0.5) / step as f32;
        }
        refine_from_full(&mut right, &full, View::Right, step, 1e3);
        for (i, d) in right.data.iter().enumerate() {
            let (x, y) = (i % w, i / w);
            if inside(x, y) {
                assert!((d - vertex(x, y)).abs() < 1e-3, "right pixel {i}: {d} against {}", vertex(x, y));
            } else {
                assert!(!d.is_finite(), "right pixel {i} stays invalid");
            }
        }
        assert!(right.data.iter().any(|d| !d.is_finite()), "the invalid pixels stay invalid");
    }
}
