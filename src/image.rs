//! Core data types: planes, colour images, cost volumes, disparity maps.
//!
//! All are a flat `Vec` plus dimensions, row-major, with the layout documented on the type. Kernels index them
//! directly; conversion from and to file formats happens only at the I/O edge (`crate::io`).

use std::borrow::Cow;

/// A single-channel image, row-major: sample (x, y) is `data()[y * width + x]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Plane<T> {
    pub(crate) width: usize,
    pub(crate) height: usize,
    pub(crate) data: Vec<T>,
}

impl<T: Clone> Plane<T> {
    /// A plane filled with `value`.
    pub fn new(width: usize, height: usize, value: T) -> Self {
        Plane { width, height, data: vec![value; width * height] }
    }
}

impl<T> Plane<T> {
    /// Wraps `width × height` samples, row-major.
    ///
    /// # Errors
    /// [`crate::error::Error::InputImage`] if `data.len()` is not `width × height`.
    pub fn from_vec(width: usize, height: usize, data: Vec<T>) -> crate::error::Result<Self> {
        if width.checked_mul(height) != Some(data.len()) {
            return Err(crate::error::Error::bad_image(format!(
                "{} samples cannot make a {width}x{height} plane",
                data.len()
            )));
        }
        Ok(Plane { width, height, data })
    }

    /// Wraps samples the crate has sized itself.
    ///
    /// # Panics
    /// If `data.len() != width * height`.
    pub(crate) fn from_parts(width: usize, height: usize, data: Vec<T>) -> Self {
        assert_eq!(data.len(), width * height, "plane data length does not match {width}x{height}");
        Plane { width, height, data }
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// (width, height).
    pub fn dims(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The samples, row-major.
    pub fn data(&self) -> &[T] {
        &self.data
    }

    /// The samples, row-major, to change in place.
    pub fn data_mut(&mut self) -> &mut [T] {
        &mut self.data
    }

    /// The samples, row-major, without a copy.
    pub fn into_data(self) -> Vec<T> {
        self.data
    }

    /// Row `y` as a slice of length `width`.
    #[inline]
    pub fn row(&self, y: usize) -> &[T] {
        &self.data[y * self.width..][..self.width]
    }

    /// Row `y` as a mutable slice of length `width`.
    #[inline]
    pub fn row_mut(&mut self, y: usize) -> &mut [T] {
        &mut self.data[y * self.width..][..self.width]
    }
}

impl<T: Copy> Plane<T> {
    /// Sample at (x, y).
    #[inline]
    pub fn at(&self, x: usize, y: usize) -> T {
        self.data[y * self.width + x]
    }

    /// The columns `x0..` of the plane.
    ///
    /// # Panics
    /// If `x0` is beyond the width.
    pub fn columns_from(&self, x0: usize) -> Self {
        Plane::from_parts(self.width - x0, self.height, columns_from(&self.data, self.width, x0))
    }

    /// The columns `range` of the plane.
    ///
    /// # Panics
    /// If `range` reaches beyond the width.
    pub(crate) fn columns(&self, range: std::ops::Range<usize>) -> Self {
        Plane::from_parts(range.len(), self.height, columns(&self.data, self.width, range))
    }
}

impl<T: Copy + Send + Sync> Plane<T> {
    /// The plane moved by (dx, dy): sample (x, y) takes what (x + dx, y + dy) held, `fill` where that is outside.
    pub(crate) fn shifted(&self, dx: i64, dy: i64, fill: T) -> Self {
        use rayon::prelude::*;
        let (w, h) = (self.width, self.height);
        let mut out = Plane::new(w, h, fill);
        out.data.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, row)| {
            let sy = y as i64 + dy;
            if sy < 0 || sy >= h as i64 {
                return;
            }
            let src = self.row(sy as usize);
            for (x, o) in row.iter_mut().enumerate() {
                let sx = x as i64 + dx;
                if sx >= 0 && sx < w as i64 {
                    *o = src[sx as usize];
                }
            }
        });
        out
    }
}

/// `storage` resized to `len` values, for a buffer whose every value is written before it is read: a fresh
/// allocation is zeroed by the OS (no fill pass); a reused one keeps what it held (only a grown part is zeroed, in
/// parallel), so a buffer carried from one run to the next is not page-faulted again.
pub(crate) fn reuse_storage(mut storage: Vec<f32>, len: usize) -> Vec<f32> {
    if storage.capacity() == 0 {
        return vec![0.0; len];
    }
    if storage.len() >= len {
        storage.truncate(len);
    } else {
        let grow = len - storage.len();
        storage.reserve_exact(grow);
        rayon::iter::ParallelExtend::par_extend(&mut storage, rayon::iter::repeat_n(0.0, grow));
    }
    storage
}

/// The columns `x0..` of every row of a row-major buffer `width` values wide.
fn columns_from<T: Copy>(data: &[T], width: usize, x0: usize) -> Vec<T> {
    columns(data, width, x0..width)
}

/// The columns `range` of a row-major `width`-wide buffer.
fn columns<T: Copy>(data: &[T], width: usize, range: std::ops::Range<usize>) -> Vec<T> {
    assert!(range.start <= range.end && range.end <= width, "columns {range:?} are beyond the width {width}");
    let mut out = Vec::with_capacity(data.len() / width.max(1) * range.len());
    for row in data.chunks_exact(width.max(1)) {
        out.extend_from_slice(&row[range.clone()]);
    }
    out
}

/// A disparity map of the left (or right) view in pixels; `f32::INFINITY` marks an invalid/unknown pixel
/// (the Middlebury convention).
pub type DisparityMap = Plane<f32>;

/// A planar RGB image with `f32` samples in 0..=255 (8-bit scale, whatever the file's bit depth): channel `c` of
/// pixel (x, y) is `channel(c)[y * width + x]`.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbImage {
    pub(crate) width: usize,
    pub(crate) height: usize,
    pub(crate) channels: [Vec<f32>; 3],
}

impl RgbImage {
    /// A black image.
    pub fn new(width: usize, height: usize) -> Self {
        let n = width * height;
        RgbImage { width, height, channels: [vec![0.0; n], vec![0.0; n], vec![0.0; n]] }
    }

    /// An image from its red, green and blue planes, each `width × height` samples, row-major.
    ///
    /// # Errors
    /// [`crate::error::Error::InputImage`] if a plane has another length, or a sample is not finite.
    pub fn from_channels(width: usize, height: usize, channels: [Vec<f32>; 3]) -> crate::error::Result<Self> {
        let n = width.checked_mul(height);
        if let Some(c) = channels.iter().find(|c| Some(c.len()) != n) {
            return Err(crate::error::Error::bad_image(format!(
                "{} samples cannot make a {width}x{height} channel",
                c.len()
            )));
        }
        if channels.iter().flatten().any(|v| !v.is_finite()) {
            return Err(crate::error::Error::bad_image("an image sample is not finite"));
        }
        Ok(RgbImage { width, height, channels })
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// Channel `c` (0 red, 1 green, 2 blue), row-major.
    ///
    /// # Panics
    /// If `c` > 2.
    pub fn channel(&self, c: usize) -> &[f32] {
        &self.channels[c]
    }

    /// Channel `c` (0 red, 1 green, 2 blue), row-major, to change in place (samples stay on the 0..=255 scale).
    ///
    /// # Panics
    /// If `c` > 2.
    pub fn channel_mut(&mut self, c: usize) -> &mut [f32] {
        &mut self.channels[c]
    }

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.width * self.height
    }

    /// True for a 0×0 image.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// (width, height).
    pub fn dims(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The colour of pixel index `i` (= `y * width + x`).
    #[inline]
    pub fn rgb(&self, i: usize) -> [f32; 3] {
        [self.channels[0][i], self.channels[1][i], self.channels[2][i]]
    }

    /// Luma (ITU-R BT.601 weights), 0..=255.
    pub fn to_grey(&self) -> Plane<f32> {
        let [r, g, b] = &self.channels;
        let [wr, wg, wb] = crate::imgproc::noise::GREY_WEIGHTS;
        let data = r.iter().zip(g).zip(b).map(|((&r, &g), &b)| wr * r + wg * g + wb * b).collect();
        Plane::from_parts(self.width, self.height, data)
    }

    /// The columns `x0..` of the image.
    ///
    /// # Panics
    /// If `x0` is beyond the width.
    pub fn columns_from(&self, x0: usize) -> RgbImage {
        let channels = self.channels.each_ref().map(|c| columns_from(c, self.width, x0));
        RgbImage { width: self.width - x0, height: self.height, channels }
    }

    /// The columns `..x1` of the image.
    ///
    /// # Panics
    /// If `x1` is beyond the width.
    pub(crate) fn columns_to(&self, x1: usize) -> RgbImage {
        let channels = self.channels.each_ref().map(|c| columns(c, self.width, 0..x1));
        RgbImage { width: x1, height: self.height, channels }
    }

    /// The image mirrored left-right. Matching the right view against the left is the left-view problem on
    /// mirrored images, which lets one implementation serve both views.
    pub fn mirrored(&self) -> RgbImage {
        let mut out = RgbImage::new(self.width, self.height);
        for (dst, src) in out.channels.iter_mut().zip(&self.channels) {
            for (drow, srow) in dst.chunks_exact_mut(self.width).zip(src.chunks_exact(self.width)) {
                for (d, s) in drow.iter_mut().zip(srow.iter().rev()) {
                    *d = *s;
                }
            }
        }
        out
    }
}

/// A matching cost volume, labels innermost: `data[(y * width + x) * ndisp + d]`.
///
/// Entry `d` at (x, y) is the cost of matching left pixel (x, y) with right pixel (x − d, y) (for a left-view
/// volume). Labels innermost is what the lattice filter and the mean-field update want: all labels of one pixel
/// are one contiguous slice.
#[derive(Clone, Debug, PartialEq)]
pub struct CostVolume {
    /// Width in pixels.
    pub(crate) width: usize,
    /// Height in pixels.
    pub(crate) height: usize,
    /// Number of disparity labels (0..ndisp).
    pub(crate) ndisp: usize,
    /// `width * height * ndisp` costs.
    pub(crate) data: Vec<f32>,
}

impl CostVolume {
    /// A volume filled with `value`.
    pub fn new(width: usize, height: usize, ndisp: usize, value: f32) -> Self {
        CostVolume { width, height, ndisp, data: vec![value; width * height * ndisp] }
    }

    /// The costs, without a copy (to reuse the storage).
    pub fn into_data(self) -> Vec<f32> {
        self.data
    }

    /// The costs of pixel index `i` (= `y * width + x`), one per label.
    #[inline]
    pub fn pixel(&self, i: usize) -> &[f32] {
        &self.data[i * self.ndisp..][..self.ndisp]
    }

    /// Mutable costs of pixel index `i`.
    #[inline]
    pub fn pixel_mut(&mut self, i: usize) -> &mut [f32] {
        &mut self.data[i * self.ndisp..][..self.ndisp]
    }

    /// The columns `x0..` of the volume, all labels, moved to the front of its own storage (no new allocation:
    /// row by row, each row moved towards the start, so no row is overwritten before it has moved).
    ///
    /// # Panics
    /// If `x0` is beyond the width.
    pub fn into_columns_from(mut self, x0: usize) -> CostVolume {
        assert!(x0 <= self.width, "column {x0} is beyond the width {}", self.width);
        let (row, kept) = (self.width * self.ndisp, (self.width - x0) * self.ndisp);
        for y in 0..self.height {
            self.data.copy_within(y * row + x0 * self.ndisp..(y + 1) * row, y * kept);
        }
        self.data.truncate(self.height * kept);
        CostVolume { width: self.width - x0, ..self }
    }
}

/// A rectified stereo pair and its disparity search range. The views are borrowed from the caller where they
/// can be ([`StereoPair::borrowed`]: a match does not copy its input) and owned where a stage makes new ones.
#[derive(Clone, Debug)]
pub struct StereoPair<'a> {
    /// Left view (the reference view: disparities are computed for it).
    pub(crate) left: Cow<'a, RgbImage>,
    /// Right view.
    pub(crate) right: Cow<'a, RgbImage>,
    /// Number of disparity labels: disparities 0..ndisp−1 are searched.
    pub(crate) ndisp: usize,
}

impl StereoPair<'static> {
    /// A pair that owns its views; checks sizes and the search range.
    ///
    /// # Errors
    /// As [`StereoPair::borrowed`].
    pub fn new(left: RgbImage, right: RgbImage, ndisp: usize) -> crate::error::Result<Self> {
        Self::checked(Cow::Owned(left), Cow::Owned(right), ndisp)
    }
}

impl<'a> StereoPair<'a> {
    /// A pair of borrowed views; checks sizes and the search range.
    ///
    /// # Errors
    /// [`crate::error::Error::SizeMismatch`] for unequal sizes, [`crate::error::Error::InvalidParam`] for an impossible `ndisp`
    /// or an empty image.
    pub fn borrowed(left: &'a RgbImage, right: &'a RgbImage, ndisp: usize) -> crate::error::Result<Self> {
        Self::checked(Cow::Borrowed(left), Cow::Borrowed(right), ndisp)
    }

    fn checked(left: Cow<'a, RgbImage>, right: Cow<'a, RgbImage>, ndisp: usize) -> crate::error::Result<Self> {
        if left.dims() != right.dims() {
            return Err(crate::error::Error::SizeMismatch { left: left.dims(), right: right.dims() });
        }
        if left.is_empty() {
            return Err(crate::error::Error::bad_image("the images are empty (0 pixels)"));
        }
        if ndisp == 0 || ndisp >= left.width {
            return Err(crate::error::Error::param(
                "ndisp",
                ndisp,
                format!("at least 1 and less than the image width {}", left.width),
            ));
        }
        Ok(StereoPair { left, right, ndisp })
    }

    /// The left view.
    pub fn left(&self) -> &RgbImage {
        &self.left
    }

    /// The right view.
    pub fn right(&self) -> &RgbImage {
        &self.right
    }

    /// The number of disparity labels (disparities 0..ndisp−1).
    pub fn ndisp(&self) -> usize {
        self.ndisp
    }

    /// The pair with views of its own (a copy of what it borrowed).
    pub fn into_owned(self) -> StereoPair<'static> {
        StereoPair {
            left: Cow::Owned(self.left.into_owned()),
            right: Cow::Owned(self.right.into_owned()),
            ndisp: self.ndisp,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_from_keeps_the_right_part_of_every_row() {
        let p = Plane::from_parts(3, 2, vec![1, 2, 3, 4, 5, 6]);
        assert_eq!(p.columns_from(1).data, vec![2, 3, 5, 6]);
        assert_eq!(p.columns_from(3).dims(), (0, 2));
        let mut img = RgbImage::new(3, 2);
        img.channels[2] = vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        assert_eq!(img.columns_from(2).channels[2], vec![3.0, 6.0]);
        // Two labels per pixel, moved within the volume's own storage.
        let vol = CostVolume { width: 3, height: 2, ndisp: 2, data: (1..=12).map(|v| v as f32).collect() };
        let kept = vol.into_columns_from(1);
        assert_eq!((kept.width, kept.height, kept.ndisp), (2, 2, 2));
        assert_eq!(kept.data, vec![3.0, 4.0, 5.0, 6.0, 9.0, 10.0, 11.0, 12.0]);
    }

    #[test]
    fn reused_storage_has_the_length_asked_for() {
        assert_eq!(reuse_storage(Vec::new(), 3), vec![0.0; 3]);
        assert_eq!(reuse_storage(vec![7.0; 5], 2), vec![7.0; 2]);
        assert_eq!(reuse_storage(vec![7.0; 2], 4), vec![7.0, 7.0, 0.0, 0.0]);
    }
}
