//! The tools around the compiler: evaluation on simulated scans, scan input
//! and output, synthetic maps and figures. They use [`crate::compiler`]; the
//! compiler does not use them.

pub mod disturb;
pub mod eval;
pub mod figures;
pub mod plot;
pub mod recording;
pub mod render;
pub mod scanio;
pub mod synth;
