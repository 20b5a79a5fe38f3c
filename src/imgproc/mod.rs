//! Image primitives the stages share: filters ([`filter`]: padding, gradients, local means, the Gaussian blur),
//! sampling between pixels ([`sample`]), order statistics ([`stats`]) and how noise carries into the grey
//! ([`noise`]). A stage that needs one imports it from
//! here, never from another stage.

pub(crate) mod filter;
pub(crate) mod noise;
pub(crate) mod sample;
pub(crate) mod stats;
