//! Image primitives the stages share: filters ([`filter`]: padding, gradients, local means, the Gaussian blur),
//! sampling between pixels ([`sample`]) and order statistics ([`stats`]). A stage that needs one imports it from
//! here, never from another stage.

pub(crate) mod filter;
pub(crate) mod sample;
pub(crate) mod stats;
