//! Statistics shared by the conditioning stages: percentiles and histograms of grey levels.

/// The values at fractions `a` and `b` of the sorted data (nearest rank), non-finite values left out.
pub(super) fn percentiles(data: &[f32], a: f64, b: f64) -> (f32, f32) {
    let mut v: Vec<f32> = data.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return (0.0, 0.0);
    }
    (crate::cost::rank_value(&mut v, a), crate::cost::rank_value(&mut v, b))
}

/// The 256-bin histogram of grey levels (each value rounded and clamped to 0..=255).
pub(super) fn histogram(data: &[f32]) -> [u64; 256] {
    let mut h = [0u64; 256];
    for v in data {
        h[v.round().clamp(0.0, 255.0) as usize] += 1;
    }
    h
}
