//! The crate's stages and their data, for the benches, the tuning examples and the tests that check a stage
//! against a reference. Not part of the API: names and signatures here change without notice. A user matches
//! through [`crate::Matcher`].

pub use crate::image::{CostVolume, StereoPair};
pub use crate::pipeline::{PipelineOutput, RunOptions, run, run_observed, run_with, tile::run_tiled};
pub use crate::rng::SplitMix64;
pub use crate::setup::strategy::TilePlan;

/// The matching cost ([`build_cost_volume`](cost::build_cost_volume) and the right view's volume).
pub mod cost {
    pub use crate::cost::{build_cost_volume, derive_right_volume, derive_right_volume_in, truncation_cost};
}

/// The permutohedral lattice of the fully connected term.
pub mod lattice {
    pub use crate::lattice::{Lattice, LatticeScratch};
}

/// Mean-field inference.
pub mod meanfield {
    pub use crate::meanfield::{MeanField, PairwiseWeights, decode_marginals, infer_mean_field};
}

/// Post-processing: the left-right check, the fill, the weighted median, the slanted planes, the sub-pixel
/// refinement.
pub mod post {
    pub use crate::post::{fill, lr_check, planes, subpixel, wmedian};
}

/// Conditioning: the vertical offset between the views.
pub mod vertical {
    pub use crate::condition::vertical::{VerticalOffset, resample_right};
}

/// The checks of a pair that no map could make right.
pub mod diagnose {
    pub use crate::diagnose::{check_answer, check_pair, check_repetition};
}
