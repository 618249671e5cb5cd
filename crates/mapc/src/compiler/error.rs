//! [`BuildError`]: why a build (options, compile, index, database size)
//! failed, with the values that made it fail.

use refloc::BadParam;

/// Why [`crate::compiler::pipeline::build`] (or one of its steps) refused
/// to build a database. Map-file problems are [`crate::compiler::mapfile::MapError`].
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BuildError {
    /// A build option gives a runtime parameter out of its range.
    #[error("invalid option: {0}")]
    Option(BadParam),
    /// The parameters given to [`crate::compiler::compile::compile`] are out of range.
    #[error("invalid parameter: {0}")]
    Param(BadParam),
    /// The fit produced a parameter out of range.
    #[error("invalid fitted parameter: {0}")]
    FittedParam(BadParam),
    /// More than two partial-view window widths.
    #[error("at most two --fov-windows widths (got {given})")]
    TooManyWindows {
        /// How many were given.
        given: usize,
    },
    /// `--accept-confidence` outside 0..=1 (or not a number).
    #[error("--accept-confidence must be within 0..=1, got {0}")]
    AcceptConfidence(f32),
    /// The map has no place wide enough for a reference site.
    #[error("no reference sites: the map has no free space wide enough for the robot")]
    NoSites,
    /// The obstacle bits given to the compiler do not cover the grid.
    #[error("grid bits shorter than the grid ({width} x {height} cells)")]
    GridBits {
        /// Grid width (cells).
        width: u32,
        /// Grid height (cells).
        height: u32,
    },
    /// The grid has more cells than a bit grid can address.
    #[error("grid too large ({width} x {height} cells)")]
    GridTooLarge {
        /// Grid width (cells).
        width: u32,
        /// Grid height (cells).
        height: u32,
    },
    /// The database would exceed `--max-db-bytes`.
    #[error(
        "the database would take about {total} bytes: {sites} reference sites of up to \
         {per_site} bytes each (for {free_cells} free cells at {resolution} m per cell) plus the \
         grid and distance map; the limit is {limit} bytes (--max-db-bytes raises it), and \
         --no-ssm-features leaves out the stored SSM features"
    )]
    TooLarge {
        /// Bytes of every section but the index and the manifest, the
        /// stored SSM features counted at their largest
        /// ([`crate::compiler::compile::DbSize`]).
        total: u64,
        /// Reference sites placed.
        sites: u64,
        /// Bytes per site (at most).
        per_site: u64,
        /// Free cells of the map.
        free_cells: usize,
        /// Map resolution (m per cell).
        resolution: f64,
        /// The limit (bytes).
        limit: u64,
    },
    /// The coarse-search index options or inputs are wrong.
    #[error(transparent)]
    Index(#[from] crate::compiler::index::IndexError),
    /// The build manifest could not be written as JSON.
    #[error("manifest: {0}")]
    Manifest(#[from] serde_json::Error),
}
