//! A database's reference side for a sensor of shorter reach, derived from
//! the database itself.
//!
//! The sites' reference scans, their PGR histograms (whole and windowed),
//! the SSM logistic weights and the stored SSM features all depend on how
//! far the reference sensor reaches (`params.sensor.range_max`). A scan from
//! a sensor that sees much less than that (a 3.5-8 m scanner on a database
//! built for 30 m) compares badly with them, and a database built for its
//! reach (`mapc build --range-max R`) answers it much better
//! (docs/results.md, "Short-range sensors on a default database").
//! [`derive_for_reach`] makes those sections again for reach `R` from what
//! the database holds (its beam grid, distance map and sites), with the
//! compiler's own code ([`crate::compiler::compile`]); the grid, the
//! distance map, the sites and the decision model are the database's own.
//! No map file is needed, so `mapc localize` can do it for the scans it is
//! given.

use refloc::format::{encode, SectionKind};
use refloc::refine::{DistMap, CLEARANCE_MARGIN_CELLS};
use refloc::RefDb;

use crate::compiler::compile::{self, CompileInput, Compiled, SiteIn};
use crate::compiler::error::BuildError;

/// The SSM logistic fit's simulated queries and seed for a derived
/// database: those of `mapc build`'s defaults
/// ([`crate::compiler::pipeline::BuildConfig`]).
pub const DERIVED_FIT_QUERIES: usize = 150;

/// Seed of the derived database's fit (`mapc build`'s default seed).
pub const DERIVED_FIT_SEED: u64 = 1;

/// The sections of `db` with its reference side made again for a sensor
/// reaching `reach_m` metres (the sensor's `range_max`; every other
/// parameter is the database's): reference scans, histograms, window
/// histograms, SSM weights (fitted again on the map's own simulated scans,
/// [`DERIVED_FIT_QUERIES`], [`DERIVED_FIT_SEED`]), and the SSM features
/// when `db` stores them. The beam grid, the distance map, the sites and
/// the decision section are copied from `db`; no coarse-search index is
/// made (the coarse stage then scores every site). Deterministic.
///
/// With `full_search` the derived parameters also switch every early stop
/// off (`early_accept` and `early_min` 0), as the localizer does for a
/// scan of short reach on the database itself
/// (`refloc::localize::SHORT_REACH`): places that look alike within a few
/// metres are common, and a stop on the first good match accepts them
/// (docs/results.md, "Short-range scans: a full search").
///
/// `reach_m` must be positive, finite and under the database's own reach
/// (else [`BuildError::Option`] naming `range_max`).
pub fn derive_for_reach<D: AsRef<[u8]>>(
    db: &RefDb<D>,
    reach_m: f32,
    full_search: bool,
) -> Result<Vec<(SectionKind, Vec<u8>)>, BuildError> {
    let mut params = *db.params();
    if full_search {
        params.select.early_accept = 0.0;
        params.select.early_min = 0;
    }
    if !(reach_m.is_finite() && reach_m > params.sensor.range_min)
        || reach_m >= params.sensor.range_max
    {
        return Err(BuildError::Option(refloc::BadParam {
            field: "range_max",
            value: reach_m as f64,
        }));
    }
    params.sensor.range_max = reach_m;
    let (width, height) = db.grid_size();
    let frame = db.frame();
    let blocked: Vec<u32> = db
        .section(SectionKind::Grid)
        .chunks_exact(4)
        .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
        .collect();
    // The fit draws its simulated poses where the clearance is at least
    // 0.25 m; the stored distance map gives it to a fraction of a cell.
    let dm = DistMap::of(db);
    let sq_dist: Vec<f32> = (0..height)
        .flat_map(|cy| (0..width).map(move |cx| (cx, cy)))
        .map(|(cx, cy)| {
            let d = (dm.clearance(cx, cy) + CLEARANCE_MARGIN_CELLS).max(0.0);
            d * d
        })
        .collect();
    let sites: Vec<SiteIn> = db
        .sites()
        .iter()
        .enumerate()
        .map(|(i, s)| SiteIn {
            x: s.x.get() as f64,
            y: s.y.get() as f64,
            clearance: s.clearance.get() as f64,
            kind: s.kind.get(),
            neighbours: db.neighbors(i).to_vec(),
        })
        .collect();
    let meta = db.meta();
    let input = CompileInput {
        width,
        height,
        frame,
        blocked: &blocked,
        sq_dist: &sq_dist,
        dist: Some(db.section(SectionKind::Dist)),
        unknown_blocks: meta.unknown_blocks.get() != 0,
        free_cells: meta.free_cells.get(),
        params,
        fit_queries: DERIVED_FIT_QUERIES,
        fit_seed: DERIVED_FIT_SEED,
    };
    let Compiled {
        mut sections,
        params,
        scans,
        ..
    } = compile::compile(&input, &sites)?;
    let decision = db.section(SectionKind::Decision);
    if !decision.is_empty() {
        sections.push((SectionKind::Decision, decision.to_vec()));
    }
    if !db.section(SectionKind::Features).is_empty() {
        sections.push((
            SectionKind::Features,
            compile::features_section(&scans, &params),
        ));
    }
    let manifest = serde_json::json!({
        "generator": "mapc",
        "derived": {"reach_m": reach_m, "full_search": full_search, "fit_queries": DERIVED_FIT_QUERIES, "fit_seed": DERIVED_FIT_SEED},
    });
    sections.push((SectionKind::Manifest, serde_json::to_vec(&manifest)?));
    Ok(sections)
}

/// A `.refdb` holding `sections`, in memory (the bytes
/// [`crate::compiler::writer::write_refdb`] would write) as a 4-byte
/// aligned copy, which `refloc::RefDb` reads in place: the words and the
/// length in bytes.
pub fn encode_aligned(sections: &[(SectionKind, Vec<u8>)]) -> (Vec<u32>, usize) {
    let refs: Vec<(SectionKind, &[u8])> =
        sections.iter().map(|(k, b)| (*k, b.as_slice())).collect();
    let mut out = Vec::new();
    let _ = encode(&refs, |b| -> Result<(), core::convert::Infallible> {
        out.extend_from_slice(b);
        Ok(())
    });
    let mut words = vec![0u32; out.len().div_ceil(4)];
    zerocopy::IntoBytes::as_mut_bytes(&mut words[..])[..out.len()].copy_from_slice(&out);
    (words, out.len())
}

#[cfg(test)]
mod tests;
