//! Post-processing after inference (paper §4), in pipeline order:
//! left-right check → occlusion fill → weighted median at the filled pixels → slanted-plane smoothing → weighted
//! median at depth edges → sub-pixel refinement from the images.

pub(crate) mod confidence;
pub mod fill;
pub mod lr_check;
pub mod planes;
pub mod subpixel;
pub mod wmedian;
