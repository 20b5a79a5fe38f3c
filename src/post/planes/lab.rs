//! The colour space of the superpixels' colour term (slanted-plane smoothing, paper §4.3): sRGB (0..255, 8-bit
//! values looked up in a table) → linear → XYZ (D65) → CIE L*a*b*, with L in 0..100; the cube root is a bit-trick
//! estimate refined by Newton steps (relative error < 1e-6, tested). Output: three row-major `f32` planes (L, a, b),
//! one value per pixel.

use rayon::prelude::*;

use crate::image::RgbImage;

/// CIE L*a*b* (D65 white) of an sRGB image with samples in 0..=255: L in 0..100, a and b roughly ±100.
pub(super) fn rgb_to_lab(image: &RgbImage) -> [Vec<f32>; 3] {
    fn srgb_to_linear(v: f32) -> f32 {
        let c = (v / 255.0).clamp(0.0, 1.0);
        if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
    }
    // 8-bit inputs (integers) are looked up; others (from 16-bit files) computed.
    let table: Vec<f32> = (0..256).map(|v| srgb_to_linear(v as f32)).collect();
    let linear =
        |v: f32| if (0.0..=255.0).contains(&v) && v == v.trunc() { table[v as usize] } else { srgb_to_linear(v) };
    fn f(t: f32) -> f32 {
        // (6/29)³ and the linear segment below it, from the CIE definition.
        const E: f32 = 216.0 / 24389.0;
        if t > E { cbrt_fast(t) } else { t * (841.0 / 108.0) + 4.0 / 29.0 }
    }
    let n = image.len();
    let mut lab = [vec![0.0f32; n], vec![0.0; n], vec![0.0; n]];
    let [l_out, a_out, b_out] = &mut lab;
    let [r, g, b] = &image.channels;
    (l_out, a_out, b_out, r, g, b).into_par_iter().with_min_len(4096).for_each(|(lo, ao, bo, &r, &g, &b)| {
        let (r, g, b) = (linear(r), linear(g), linear(b));
        // sRGB → XYZ (D65), divided by the white point (0.95047, 1, 1.08883).
        let x = (0.412_456_4 * r + 0.357_576_1 * g + 0.180_437_5 * b) / 0.950_47;
        let y = 0.212_672_9 * r + 0.715_152_2 * g + 0.072_175 * b;
        let z = (0.019_333_9 * r + 0.119_192 * g + 0.950_304_1 * b) / 1.088_83;
        let (fx, fy, fz) = (f(x), f(y), f(z));
        *lo = 116.0 * fy - 16.0;
        *ao = 500.0 * (fx - fy);
        *bo = 200.0 * (fy - fz);
    });
    lab
}

/// Cube root of t > 0 to within 1e-6 relative (tested): an exponent-bits estimate refined by three Newton steps.
/// Several times cheaper than libm's `cbrtf`, which dominated the colour conversion.
#[inline]
fn cbrt_fast(t: f32) -> f32 {
    // Dividing the biased exponent by 3: bits/3 + (2/3)·127·2²³ gives a first guess within ~6%.
    let mut y = f32::from_bits(t.to_bits() / 3 + 709_921_077);
    for _ in 0..3 {
        y -= (y * y * y - t) / (3.0 * y * y);
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lab_of_known_colours() {
        let mut img = RgbImage::new(3, 1);
        for c in 0..3 {
            img.channels[c][1] = 255.0;
        }
        img.channels[0][2] = 255.0;
        let lab = rgb_to_lab(&img);
        // Black, white, pure red (L 53.24, a 80.09, b 67.20 in the usual tables).
        assert!(lab[0][0].abs() < 1e-4 && lab[1][0].abs() < 1e-4 && lab[2][0].abs() < 1e-4);
        assert!((lab[0][1] - 100.0).abs() < 1e-2 && lab[1][1].abs() < 1e-2 && lab[2][1].abs() < 1e-2);
        assert!(
            (lab[0][2] - 53.24).abs() < 0.02 && (lab[1][2] - 80.09).abs() < 0.05 && (lab[2][2] - 67.20).abs() < 0.05
        );
    }

    #[test]
    fn fast_cbrt_matches_std() {
        let mut worst = 0.0f64;
        let mut t = 216.0f32 / 24389.0;
        while t < 1.2 {
            worst = worst.max((f64::from(cbrt_fast(t)) - f64::from(t).cbrt()).abs() / f64::from(t).cbrt());
            t *= 1.0001;
        }
        assert!(worst < 1e-6, "worst relative error {worst}");
    }
}
