//! mapc: the refloc map compiler (library half).
//!
//! Stages, one module each: [`mapfile`] (ROS map_server YAML + PGM/PNG),
//! [`edt`] (exact Euclidean distance transform), [`gvd`] (generalized Voronoi
//! diagram and its graph), [`sites`] (reference site placement and coverage).
#![deny(missing_docs)]

pub mod compile;
pub mod disturb;
pub mod edt;
pub mod eval;
pub mod figures;
pub mod fit;
pub mod gvd;
pub mod index;
pub mod mapfile;
pub mod pipeline;
pub mod plot;
pub mod recording;
pub mod render;
pub mod rng;
pub mod scanio;
pub mod sim;
pub mod sites;
pub mod synth;
pub mod testdata;
pub mod writer;
