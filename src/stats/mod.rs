//! Probability building blocks below the forward model and the inference: the priors of
//! parameters and effects ([`prior`]) and special functions ([`special`]: the chi-square
//! upper tail, the standard normal quantile).

pub mod prior;
pub mod special;
