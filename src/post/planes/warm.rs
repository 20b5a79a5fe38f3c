//! A segmentation carried from one frame of a sequence to the next (our addition): a panning camera's next frame
//! shows the same surfaces a few pixels on, so the previous frame's segments and planes, moved with them, are
//! nearly where this frame's converge, and the alternation starts there instead of on a grid.
//!
//! Moving a segmentation leaves pixels that nothing covers (the strip the camera has just brought into view), and
//! the pixels where the frames disagree (disocclusions, moving objects) are let go: both get cells of the initial
//! grid, as a first frame's pixels do; the strip's cells, a few pixels wide, join a neighbour while it stays near a
//! cell's size. Pixels moved out of view take their segments' parts with them, which can cut a segment in two: every
//! 4-connected piece becomes a segment of its own (the sweep's connectivity test assumes it), with its old plane.

use super::segments::grid_labels;
use crate::image::Plane;

/// Marks a pixel without a segment: in view only in the current frame.
pub(crate) const UNCOVERED: u32 = u32::MAX;
/// Marks a pixel whose segment was let go: the frames disagree there.
pub(crate) const RELEASED: u32 = u32::MAX - 1;

/// The segments and planes the slanted-plane smoothing ended with on one frame.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Segmentation {
    /// Segment per pixel; [`UNCOVERED`] or [`RELEASED`] where a moved segmentation says nothing.
    pub(crate) labels: Plane<u32>,
    /// `[a, b, c]` per segment: d(x, y) = a·x + b·y + c.
    pub(crate) planes: Vec<[f64; 3]>,
}

impl Segmentation {
    /// The segmentation moved as [`crate::temporal`] moves an answer by a shift: pixel (x, y) takes the segment of
    /// (x + dx, y + dy) ([`UNCOVERED`] where that is outside), and each plane moves with its segment.
    pub(crate) fn shifted(&self, dx: i64, dy: i64) -> Segmentation {
        // d'(x, y) = d(x + dx, y + dy).
        let planes = self.planes.iter().map(|&[a, b, c]| [a, b, c + a * dx as f64 + b * dy as f64]).collect();
        Segmentation { labels: self.labels.shifted(dx, dy, UNCOVERED), planes }
    }

    /// Lets go of the segments of the pixels where `released` is true ([`RELEASED`]; uncovered pixels stay so).
    pub(crate) fn release(&mut self, released: &[bool]) {
        let covered = self.labels.data.iter_mut().zip(released).filter(|(l, r)| **r && **l != UNCOVERED);
        covered.for_each(|(l, _)| *l = RELEASED);
    }
}

/// A carried segmentation made ready to start from: uncovered and released pixels get the cells of the grid of
/// `step` they lie in, every 4-connected piece of a segment becomes a segment, and the small pieces of the strip
/// (uncovered, or released beside what is) join a neighbour ([`merge_small`]); segments are numbered in raster order
/// of first appearance. Returns the labels and each segment's plane (`None` for the new cells, which have none yet).
pub(super) fn restart_from(start: &Segmentation, step: f64) -> (Vec<u32>, Vec<Option<[f64; 3]>>) {
    let (w, h) = start.labels.dims();
    let (grid, cells) = grid_labels(w, h, step);
    let (old, cells) = (start.planes.len() as u64, cells as u64);
    // Old segments keep their ids below `old`, the uncovered cells follow them, then the released ones.
    let source: Vec<u64> = start
        .labels
        .data
        .iter()
        .zip(&grid)
        .map(|(&l, &g)| match l {
            UNCOVERED => old + u64::from(g),
            RELEASED => old + cells + u64::from(g),
            l => u64::from(l),
        })
        .collect();
    let (pieces, sources) = connected_pieces(&source, w, h);
    let planes: Vec<_> = sources.iter().map(|&from| (from < old).then(|| start.planes[from as usize])).collect();
    // The strip: the uncovered pieces, and the released ones beside them (the frames' comparison cannot reach
    // into the strip, so it lets go of a margin along it).
    let kind = |from: u64| (from >= old, (old..old + cells).contains(&from));
    let mut strip: Vec<bool> = sources.iter().map(|&from| kind(from).1).collect();
    neighbour_pairs(&pieces, w, |a, b| {
        let ((new_a, unc_a), (new_b, unc_b)) = (kind(sources[a as usize]), kind(sources[b as usize]));
        if new_a && unc_b {
            strip[a as usize] = true;
        }
        if new_b && unc_a {
            strip[b as usize] = true;
        }
    });
    merge_small(&pieces, &planes, &strip, w, step)
}

/// Calls `f` with the labels of every two 4-neighbouring pixels of a `w` pixels wide image, each pair once.
fn neighbour_pairs(labels: &[u32], w: usize, mut f: impl FnMut(u32, u32)) {
    for (i, &a) in labels.iter().enumerate() {
        if i % w + 1 < w {
            f(a, labels[i + 1]);
        }
        if let Some(&below) = labels.get(i + w) {
            f(a, below);
        }
    }
}

/// The 4-connected pieces of equal `source` values, numbered in raster order of first appearance, and each
/// piece's source value.
fn connected_pieces(source: &[u64], w: usize, h: usize) -> (Vec<u32>, Vec<u64>) {
    let mut labels = vec![UNCOVERED; w * h];
    let mut sources = Vec::new();
    let mut stack = Vec::new();
    for first in 0..w * h {
        if labels[first] != UNCOVERED {
            continue;
        }
        let id = sources.len() as u32;
        let from = source[first];
        sources.push(from);
        labels[first] = id;
        stack.push(first);
        while let Some(i) = stack.pop() {
            let (x, y) = (i % w, i / w);
            let nbrs = [
                (x > 0).then(|| i - 1),
                (x + 1 < w).then(|| i + 1),
                (y > 0).then(|| i - w),
                (y + 1 < h).then(|| i + w),
            ];
            for j in nbrs.into_iter().flatten() {
                if labels[j] == UNCOVERED && source[j] == from {
                    labels[j] = id;
                    stack.push(j);
                }
            }
        }
    }
    (labels, sources)
}

/// The pieces of the strip a pan uncovers (`joins`) smaller than half a grid cell join, in order, the neighbour they
/// share the longest boundary with among those they stay within one and a half cells with, and take its plane: the
/// strip's cells, a few pixels wide, would otherwise add a column of segments every frame. Joined pieces are
/// adjacent, so every segment stays connected.
fn merge_small(
    pieces: &[u32],
    planes: &[Option<[f64; 3]>],
    joins: &[bool],
    w: usize,
    step: f64,
) -> (Vec<u32>, Vec<Option<[f64; 3]>>) {
    let n = planes.len();
    let cell = step * step;
    let mut size = vec![0usize; n];
    pieces.iter().for_each(|&l| size[l as usize] += 1);
    let small: Vec<bool> = size.iter().zip(joins).map(|(&s, &j)| j && (s as f64) < 0.5 * cell).collect();
    // Shared boundary lengths (4-neighbour pixel pairs) of each small piece with each neighbour.
    let mut shared: Vec<Vec<(u32, u32)>> = vec![Vec::new(); n];
    let mut count = |a: u32, b: u32| {
        if small[a as usize] {
            let list = &mut shared[a as usize];
            match list.iter_mut().find(|(l, _)| *l == b) {
                Some((_, c)) => *c += 1,
                None => list.push((b, 1)),
            }
        }
    };
    neighbour_pairs(pieces, w, |a, b| {
        if a != b {
            count(a, b);
            count(b, a);
        }
    });
    let mut parent: Vec<u32> = (0..n as u32).collect();
    let root = |parent: &[u32], mut k: u32| {
        while parent[k as usize] != k {
            k = parent[k as usize];
        }
        k
    };
    for k in (0..n).filter(|&k| small[k]) {
        let me = root(&parent, k as u32);
        let mut best: Option<(u32, u32)> = None;
        for &(nb, c) in &shared[k] {
            let r = root(&parent, nb);
            let fits = r != me && (size[r as usize] + size[me as usize]) as f64 <= 1.5 * cell;
            if fits && best.is_none_or(|(_, bc)| c > bc) {
                best = Some((r, c));
            }
        }
        if let Some((r, _)) = best {
            parent[me as usize] = r;
            size[r as usize] += size[me as usize];
        }
    }
    // Number the joined segments in raster order of first appearance.
    let mut id = vec![UNCOVERED; n];
    let mut merged_planes = Vec::new();
    let labels = pieces
        .iter()
        .map(|&l| {
            let r = root(&parent, l) as usize;
            if id[r] == UNCOVERED {
                id[r] = merged_planes.len() as u32;
                merged_planes.push(planes[r]);
            }
            id[r]
        })
        .collect();
    (labels, merged_planes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shift_moves_labels_and_planes_and_uncovers_the_entering_strip() {
        let (w, h) = (6, 2);
        let labels = vec![0, 0, 0, 1, 1, 1, 0, 0, 0, 1, 1, 1];
        let seg =
            Segmentation { labels: Plane::from_parts(w, h, labels), planes: vec![[0.5, 0.0, 1.0], [0.0, 0.25, 3.0]] };
        let moved = seg.shifted(2, 0);
        let u = UNCOVERED;
        assert_eq!(moved.labels.data, vec![0, 1, 1, 1, u, u, 0, 1, 1, 1, u, u]);
        // The plane gives pixel (x, y) what it gave (x + 2, y).
        assert_eq!(moved.planes, vec![[0.5, 0.0, 2.0], [0.0, 0.25, 3.0]]);
    }

    #[test]
    fn a_restart_splits_cut_segments_and_gives_the_uncovered_pixels_grid_cells() {
        // Segment 0 is a U whose base left the view: two pieces. The last two columns are uncovered; with a step
        // of 1 every uncovered pixel is a cell of its own, and no piece is small.
        let u = UNCOVERED;
        let labels = vec![
            0, 1, 0, u, u, //
            0, 1, 0, u, u, //
            1, 1, 1, u, u,
        ];
        let (p0, p1) = ([0.0, 0.0, 1.0], [0.0, 0.0, 2.0]);
        let seg = Segmentation { labels: Plane::from_parts(5, 3, labels), planes: vec![p0, p1] };
        let (labels, planes) = restart_from(&seg, 1.0);
        assert_eq!(labels, vec![0, 1, 2, 3, 4, 0, 1, 2, 5, 6, 1, 1, 1, 7, 8]);
        assert_eq!(planes[..3], [Some(p0), Some(p1), Some(p0)]);
        assert!(planes[3..].iter().all(Option::is_none) && planes.len() == 9);
    }

    #[test]
    fn small_pieces_join_a_neighbour_they_stay_within_one_and_a_half_cells_with() {
        // A segment of 8 pixels and an uncovered column of 2 (a 3 px grid: cells of 9, small below 4.5): joined.
        let u = UNCOVERED;
        let p = [0.5, 0.0, 1.0];
        let seg = Segmentation { labels: Plane::from_parts(5, 2, vec![0, 0, 0, 0, u, 0, 0, 0, 0, u]), planes: vec![p] };
        let (labels, planes) = restart_from(&seg, 3.0);
        assert_eq!((labels, planes), (vec![0; 10], vec![Some(p)]));
        // A segment of 14 (one and a half cells with the column): the column stays a segment of its own, without a
        // plane yet.
        let mut labels = vec![0; 16];
        labels[7] = u;
        labels[15] = u;
        let seg = Segmentation { labels: Plane::from_parts(8, 2, labels), planes: vec![p] };
        let (labels, planes) = restart_from(&seg, 3.0);
        assert_eq!((labels[7], labels[15], labels[0]), (1, 1, 0));
        assert_eq!(planes, vec![Some(p), None]);
        // A released column inside the view (the frames disagree there: another surface, perhaps) stays a segment
        // of its own; one beside the uncovered strip joins as the strip does.
        let r = RELEASED;
        let seg = Segmentation { labels: Plane::from_parts(5, 2, vec![0, 0, r, 0, 0, 0, 0, r, 0, 0]), planes: vec![p] };
        let (labels, planes) = restart_from(&seg, 3.0);
        assert_eq!((labels[2], labels[7], planes.len()), (1, 1, 3));
        let seg = Segmentation { labels: Plane::from_parts(5, 2, vec![0, 0, 0, r, u, 0, 0, 0, r, u]), planes: vec![p] };
        let (labels, planes) = restart_from(&seg, 3.0);
        assert_eq!((labels, planes), (vec![0; 10], vec![Some(p)]));
    }
}
