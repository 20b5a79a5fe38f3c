//! What a run produces: the maps ([`PipelineOutput`]), what the adaptive front end measured ([`Measured`]) and the time
//! each stage took ([`Timings`]).

use std::time::{Duration, Instant};

use crate::condition;
use crate::image::{DisparityMap, Plane};

/// Wall-clock time spent in each stage, in pipeline order.
#[derive(Clone, Debug, Default)]
pub struct Timings {
    /// (stage name, duration) pairs.
    pub stages: Vec<(&'static str, Duration)>,
}

impl Timings {
    /// Runs `f`, recording its duration under `name`.
    pub fn time<T>(&mut self, name: &'static str, f: impl FnOnce() -> T) -> T {
        let start = Instant::now();
        let out = f();
        self.stages.push((name, start.elapsed()));
        out
    }

    /// Adds `other`'s stages to the ones of the same name (appending new names): the sums of many runs.
    pub fn add_summed(&mut self, other: &Timings) {
        for &(name, d) in &other.stages {
            match self.stages.iter_mut().find(|(n, _)| *n == name) {
                Some((_, sum)) => *sum += d,
                None => self.stages.push((name, d)),
            }
        }
    }

    /// Each stage once, its durations summed, in the order first run: what a report shows of a stage that ran more
    /// than once (in every tile, on both views).
    pub fn per_stage(&self) -> Timings {
        let mut sum = Timings::default();
        sum.add_summed(self);
        sum
    }

    /// Sum of all stages.
    pub fn total(&self) -> Duration {
        self.stages.iter().map(|(_, d)| *d).sum()
    }
}

/// What a run produces.
#[derive(Clone, Debug)]
pub struct PipelineOutput {
    /// The left view's disparity map (`inf` = invalid, when post-processing leaves holes).
    pub disparity: DisparityMap,
    /// Per-pixel confidence of the final map, 0..1, made to rank its errors (`src/post/confidence.rs`; 0 where
    /// the map is invalid); `None` unless the run was asked for it ([`super::RunOptions::confidence`]).
    pub confidence: Option<Plane<f32>>,
    /// Per-pixel max-marginal of the left view before post-processing (mean-field models; 1 for WTA): what a
    /// coarse answer's prior is weighted by.
    pub(crate) max_marginal: Plane<f32>,
    /// The pixels that passed the left-right check (all of them when it is off).
    pub consistent: Plane<bool>,
    /// Time per stage.
    pub timings: Timings,
    /// What the adaptive front end measured on the (full-resolution) pair and set from it; `None` when
    /// `[condition]` is off.
    pub measured: Option<Measured>,
    /// The right view's vertical offset that was removed, if one was (a sequence's next frame reuses it).
    pub(crate) vertical_offset: Option<crate::condition::vertical::VerticalOffset>,
    /// The segments and planes the slanted-plane smoothing ended with (a panning camera's next frame starts from
    /// them); `None` without the planes, and for tiled or reduced runs.
    pub(crate) segmentation: Option<crate::post::planes::Segmentation>,
}

/// What the adaptive front end (`crate::condition`) measured on a pair and the values it derived (`jem -v`
/// prints it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measured {
    /// Contrast gains and noise σn of both views.
    pub stats: condition::PairStats,
    /// λ of the coarse prior before its per-pixel factor (0: no prior).
    pub prior_weight: f32,
    /// λ's floor where the cost is flat (`condition.prior.flat`, × the pixel's flatness).
    pub prior_flat: f32,
    /// The Census support τ in grey levels (0: every bit compared).
    pub census_support: f32,
    /// ḡ and ε of the gradient normalisation (`None`: the raw gradient).
    pub gradient: Option<(f32, f32)>,
    /// The right view's residual vertical offset (`crate::condition::vertical`; `None`: not measured).
    pub vertical: Option<VerticalMeasured>,
}

impl std::fmt::Display for Measured {
    /// One line: what the adaptive front end measured on the pair and set from it (what `jem -v` prints).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let m = self;
        let [nl, nr] = m.stats.noise;
        let [gl, gr] = m.stats.gain;
        let gradient =
            m.gradient.map_or("raw".to_string(), |(mean, eps)| format!("local contrast {mean:.1}, ε {eps:.1}"));
        let [bl, br] = m.stats.cost_blur;
        let blur = if bl > 0.0 || br > 0.0 {
            format!("; cost blur σ {bl:.2} / {br:.2} px (sharpness matched)")
        } else {
            String::new()
        };
        let jpeg = if m.stats.is_jpeg() {
            let ([jl, jr], [bl, br]) = (m.stats.jpeg, m.stats.blocking);
            format!("; JPEG: compression error σ {jl:.2} / {jr:.2}, block steps {bl:.2} / {br:.2}")
        } else {
            String::new()
        };
        let vertical = m.vertical.map_or(String::new(), |v| {
            let (lo, hi) = v.range;
            let done = if v.corrected { "removed" } else { "left" };
            format!("; right view's vertical offset {lo:+.2} to {hi:+.2} px ({done})")
        });
        write!(
            f,
            "measured: noise σ {nl:.2} / {nr:.2}, contrast gain {gl:.2} / {gr:.2} (left / right); prior λ {:.2} \
             (at least {:.2} × the cost's flatness), Census support {:.1}, gradient {gradient}{blur}{jpeg}{vertical}",
            m.prior_weight, m.prior_flat, m.census_support
        )
    }
}

/// The JPEG compression error σ (grey levels, either view) from which a match says so without `-v`
/// ([`Measured::jpeg_note`]). The measurement reads 0 on uncompressed views and on JPEG above quality 92 or so,
/// whose steps it cannot tell from texture; at quality 90 it reads 1.6–3.1 on trainingQ, and there the weighted
/// avgErr is 1.37× the uncompressed views' (docs/RESULTS.md, robustness): every compression it sees matters.
const JPEG_NOTE_SIGMA: f32 = 1.0;

impl Measured {
    /// One line when the views were measured as JPEG-compressed with an error σ of 1 grey level or more
    /// (`None` otherwise; see `JPEG_NOTE_SIGMA`): compression costs accuracy that no setting gives back.
    pub fn jpeg_note(&self) -> Option<String> {
        let [l, r] = self.stats.jpeg;
        (l.max(r) >= JPEG_NOTE_SIGMA).then(|| {
            format!(
                "the views are JPEG-compressed (compression error σ {l:.1} / {r:.1} grey levels, left / right): at \
                 quality 90 the error on MiddEval3 is 1.37× that of the same views saved losslessly; give PNG views \
                 where the camera can write them"
            )
        })
    }
}

/// The right view's residual vertical offset as measured (`crate::condition::vertical::estimate`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VerticalMeasured {
    /// Its smallest and largest value over the image (px, at the resolution the pipeline ran at).
    pub range: (f32, f32),
    /// Whether it was removed (it reached `condition.vertical.min_px`).
    pub corrected: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timings_add_up_by_stage_name() {
        let ms = Duration::from_millis;
        let mut sum = Timings { stages: vec![("cost", ms(1))] };
        sum.add_summed(&Timings { stages: vec![("mf", ms(2)), ("cost", ms(3))] });
        sum.add_summed(&Timings { stages: vec![("mf", ms(4))] });
        assert_eq!(sum.stages, vec![("cost", ms(4)), ("mf", ms(6))]);
        let twice = Timings { stages: vec![("cost", ms(1)), ("mf", ms(2)), ("cost", ms(3))] };
        assert_eq!(twice.per_stage().stages, vec![("cost", ms(4)), ("mf", ms(2))]);
    }
}
