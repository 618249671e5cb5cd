//! mapc: the refloc map compiler (library half), in two trees by role.
//!
//! - [`compiler`]: what `mapc build` runs, map file to `.refdb`: [`compiler::mapfile`]
//!   (ROS map_server YAML + PGM/PNG), [`compiler::edt`] (exact Euclidean distance
//!   transform), [`compiler::gvd`] (generalized Voronoi diagram and its graph),
//!   [`compiler::sites`] (reference site placement and coverage),
//!   [`compiler::compile`] (reference scans and histograms), [`compiler::fit`]
//!   (the pairwise potential's weights), [`compiler::index`] (the coarse-search
//!   index), [`compiler::writer`] (the atomic writer), and [`compiler::pipeline`]
//!   (all of them as one call).
//! - [`tools`]: what is built around the compiler: evaluation ([`tools::eval`],
//!   [`tools::disturb`]), scan input and output ([`tools::scanio`],
//!   [`tools::recording`]), synthetic maps ([`tools::synth`]) and figures
//!   ([`tools::figures`], [`tools::plot`], [`tools::render`]).
//!
//! The compiler never uses the tools (a test reads its sources to check); the
//! tools use the compiler. The `mapc` binary uses both.
#![deny(missing_docs)]

pub mod compiler;
pub mod testdata;
pub mod tools;
