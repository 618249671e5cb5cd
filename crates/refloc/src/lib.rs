//! # refloc: global localization of one 2D laser scan against a compiled map
//!
//! `#![no_std]`, no heap, no I/O. A `.refdb` reference database (built by
//! `mapc build`) is read from any byte container with [`RefDb::new`]; one
//! scan is localized with no initial pose by [`localize()`], using only a
//! caller-supplied scratch buffer of [`scratch_size`] bytes.
//!
//! Pipeline, one module per stage (see `docs/architecture.md`):
//! - [`prep`]: scan points, surfaces, resampling, tangents.
//! - [`pgr`]: pairwise geometric relationships and the 2D histogram.
//! - [`rank`]: histogram correlation and the bounded best-first list
//!   (a leaf, used by `coarse` and `index`).
//! - [`coarse`]: correlation against every site, candidate count N_C.
//! - [`index`]: the optional tree over the sites' histograms that makes the
//!   coarse ranking sublinear on large maps.
//! - [`ssm`]: spectral scan matching against a candidate's reference scan.
//! - [`refine`]: pose refinement against the map's distance field.
//! - [`verify`]: the vicinity score.
//! - [`select`]: the early stop, the choice of the answer, ambiguity and
//!   acceptance.
//! - [`raycast`]: exact grid traversal, shared with the compiler.
//!
//! Units: metres and radians (REP-103), `f32`.
//!
//! ```no_run
//! # fn demo(bytes: &[u8], ranges: &[f32]) -> Result<(), Box<dyn std::error::Error>> {
//! use refloc::{localize, scratch_size, RangeScan, RefDb, Scan};
//! let db = RefDb::new(bytes)?;
//! let mut scratch = vec![0u8; scratch_size(db.params(), ranges.len())];
//! let scan = Scan::Ranges(RangeScan {
//!     angle_min: -core::f32::consts::PI,
//!     angle_increment: 2.0 * core::f32::consts::PI / ranges.len() as f32,
//!     range_min: 0.05,
//!     range_max: 30.0,
//!     ranges,
//! });
//! let fix = localize(&db, &scan, &mut scratch)?;
//! println!("{:?} accepted={}", fix.pose, fix.accepted);
//! # Ok(()) }
//! ```
//!
//! MSRV: 1.85.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![deny(missing_docs)]
// `!(x < y)` is deliberate throughout: it is true for NaN, which untrusted
// input must be able to produce without slipping past a check.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
#![cfg_attr(not(feature = "mmap"), forbid(unsafe_code))]
#![cfg_attr(feature = "mmap", deny(unsafe_code))]

pub mod coarse;
pub mod confidence;
pub mod db;
pub mod format;
pub mod frame;
pub mod index;
pub mod localize;
pub mod math;
pub mod params;
pub mod pgr;
pub mod prep;
pub mod prior;
pub mod rank;
pub mod raycast;
pub mod refine;
pub mod select;
pub mod ssm;
pub mod verify;

#[cfg(feature = "mmap")]
mod mmap;

pub use confidence::Decision;
pub use db::{DbError, DbErrorKind, RefDb};
pub use frame::{wrap_angle, MapFrame, Pose2, PoseTrig};
pub use localize::{
    localize, localize_with_prior, scratch_size, Candidate, Hypothesis, Localization,
    LocalizeError, Localizer, Prepared, RangeScan, Scan, MAX_HYPOTHESES,
};
#[cfg(feature = "mmap")]
pub use mmap::{map_file, open_mmap, OpenError};
pub use params::{
    BadParam, CoarseParams, Params, PrepParams, RefineParams, SelectParams, Selection, SensorModel,
    SsmParams, VerifyParams,
};
pub use prior::{Polygon, PolygonError, Prior};

#[cfg(test)]
mod tests;
