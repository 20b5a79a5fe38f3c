//! Post-processing after inference (paper §4), in pipeline order:
//! left-right check → occlusion fill → weighted median at the filled pixels → slanted-plane smoothing.

pub(crate) mod confidence;
pub mod fill;
pub mod lr_check;
pub mod planes;
pub mod wmedian;
