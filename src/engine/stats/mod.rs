//! Statistics that know nothing of studies: binomial intervals and tests, streamed quantiles, the
//! generalised Pareto tail fit, paired comparison of detectors on the same trials.

pub mod intervals;
pub mod paired;
pub mod quantiles;
pub mod tail;
