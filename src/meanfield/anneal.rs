//! Our additions to the temperature and coupling of the model (not in the paper), both off by default and
//! measured on trainingQ in docs/tuning-log.md ("Sweep log: LCM — annealing / label-aware temperature").
//!
//! Deterministic annealing (`unary_scale_start` > 0): the unary temperature changes over the iterations,
//! geometrically from `unary_scale_start` (the initial marginals) to `unary_scale` ([`UnarySchedule`]). Starting
//! hot (a small scale) keeps the marginals soft while the neighbours' evidence accumulates, ending cold sharpens
//! them to the unary's full strength, the classic remedy for mean field freezing into its first,
//! winner-take-all-like state.
//!
//! Label-aware local coupling (`lcm_weight_ref_labels` > 0): ω̃ is multiplied by M / reference
//! ([`label_aware_weights`]). Around the uniform marginal the softmax has slope 1/M, so a perturbation of the
//! neighbours' marginals comes back amplified by ~ω̃·Σ_j w̃(i, j)·(3 − 2β) / M: with a fixed ω̃ the local term
//! propagates evidence through diffuse regions far less for M = 190 than for M = 60 (and a hot start, which keeps
//! the marginals diffuse for longer, ruins the large-range scenes). Scaling ω̃ with M keeps that gain the same for
//! every M.

use super::PairwiseWeights;
use crate::params::MeanFieldParams;

/// The weights `weights` with the label-aware local coupling of `p` applied for `m` labels: ω̃ × m /
/// `lcm_weight_ref_labels`, or unchanged when that is 0.
pub(crate) fn label_aware_weights(weights: PairwiseWeights, p: &MeanFieldParams, m: usize) -> PairwiseWeights {
    if p.lcm_weight_ref_labels == 0 {
        return weights;
    }
    PairwiseWeights { lcm: weights.lcm * (m as f32 / p.lcm_weight_ref_labels as f32), ..weights }
}

/// The unary scale (inverse temperature of the cost) of each mean-field iteration.
///
/// Without annealing (`unary_scale_start` = 0) every iteration uses `unary_scale`. With it, step t (0 = the
/// initial marginals, 1..=T the iterations) uses s_t = s_0·(s_K / s_0)^(t/K), s_0 = `unary_scale_start`,
/// s_K = `unary_scale`, K = `unary_anneal_iterations` (0 = T): a geometric schedule, i.e. equal ratios between
/// consecutive temperatures, reaching `unary_scale` exactly at step K and staying there. With T = 0 there is
/// nothing to anneal and the initial marginals use `unary_scale`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct UnarySchedule {
    start: f32,
    end: f32,
    iterations: usize,
}

impl UnarySchedule {
    /// The schedule configured in `p`.
    pub(crate) fn new(p: &MeanFieldParams) -> Self {
        let iterations = if p.unary_anneal_iterations > 0 { p.unary_anneal_iterations } else { p.iterations };
        UnarySchedule { start: p.unary_scale_start, end: p.unary_scale, iterations }
    }

    /// The scale of step `t` (0 = the initial marginals, 1..=T the iterations).
    pub(crate) fn at(&self, t: usize) -> f32 {
        if self.start <= 0.0 || self.iterations == 0 || t >= self.iterations {
            return self.end;
        }
        let frac = t as f64 / self.iterations as f64;
        let (start, end) = (f64::from(self.start), f64::from(self.end));
        (start * (end / start).powf(frac)) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The annealing schedule: off gives `unary_scale` at every step; on, it starts at `unary_scale_start`, ends at
    /// `unary_scale` after T iterations (and stays there), and consecutive scales have a constant ratio.
    #[test]
    fn meanfield_unary_schedule_is_geometric_from_start_to_end() {
        let off = MeanFieldParams { iterations: 4, unary_scale: 0.1, ..MeanFieldParams::default() };
        assert!((0..8).all(|t| UnarySchedule::new(&off).at(t) == 0.1));
        let p = MeanFieldParams { iterations: 4, unary_scale: 0.16, unary_scale_start: 0.01, ..off };
        let s = UnarySchedule::new(&p);
        let expected = [0.01, 0.02, 0.04, 0.08, 0.16, 0.16, 0.16];
        for (t, e) in expected.iter().enumerate() {
            assert!((s.at(t) - e).abs() < 1e-7, "step {t}: {} vs {e}", s.at(t));
        }
        assert_eq!(s.at(4), 0.16, "the last iteration uses unary_scale exactly");
        // Cooling as well as heating, and T = 0 (nothing to anneal).
        let down = UnarySchedule::new(&MeanFieldParams { unary_scale_start: 0.4, ..p });
        assert!((down.at(2) - 0.4 * (0.16f32 / 0.4).sqrt()).abs() < 1e-6);
        assert_eq!(UnarySchedule::new(&MeanFieldParams { iterations: 0, ..p }).at(0), 0.16);
    }

    /// `unary_anneal_iterations` = K: the schedule reaches `unary_scale` at step K and stays there.
    #[test]
    fn meanfield_unary_schedule_holds_after_k_iterations() {
        let p = MeanFieldParams {
            iterations: 6,
            unary_scale: 0.16,
            unary_scale_start: 0.04,
            unary_anneal_iterations: 2,
            ..MeanFieldParams::default()
        };
        let s = UnarySchedule::new(&p);
        let expected = [0.04, 0.08, 0.16, 0.16, 0.16, 0.16, 0.16];
        for (t, e) in expected.iter().enumerate() {
            assert!((s.at(t) - e).abs() < 1e-7, "step {t}: {} vs {e}", s.at(t));
        }
        let all = UnarySchedule::new(&MeanFieldParams { unary_anneal_iterations: 6, ..p.clone() });
        assert_eq!(all, UnarySchedule::new(&MeanFieldParams { unary_anneal_iterations: 0, ..p }));
    }

    /// The label-aware local coupling: ω̃ × M / reference, ω untouched; off = unchanged.
    #[test]
    fn meanfield_label_aware_weights_scale_with_the_labels() {
        let w = PairwiseWeights { fcm: 7.0, lcm: 1.5 };
        assert_eq!(label_aware_weights(w, &MeanFieldParams::default(), 190), w);
        let p = MeanFieldParams { lcm_weight_ref_labels: 60, ..MeanFieldParams::default() };
        assert_eq!(label_aware_weights(w, &p, 60), w);
        assert_eq!(label_aware_weights(w, &p, 180), PairwiseWeights { fcm: 7.0, lcm: 4.5 });
    }
}
