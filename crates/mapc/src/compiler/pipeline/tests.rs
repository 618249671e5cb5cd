use super::*;
use crate::compiler::mapfile::OccupancyGrid;

/// A walled 60 x 40 room with a pillar, at `resolution` m per cell.
fn room(resolution: f64) -> MapSource {
    let rows: Vec<String> = (0..40)
        .map(|y| {
            (0..60)
                .map(|x| {
                    let wall = x == 0 || y == 0 || x == 59 || y == 39;
                    let pillar = (25..30).contains(&x) && (15..20).contains(&y);
                    if wall || pillar {
                        '#'
                    } else {
                        '.'
                    }
                })
                .collect()
        })
        .collect();
    let refs: Vec<&str> = rows.iter().map(String::as_str).collect();
    MapSource::in_memory(
        OccupancyGrid::from_ascii(&refs, resolution, [0.0; 3]),
        "room.pgm",
    )
}

/// The default options without the logistic fit.
fn quick() -> BuildConfig {
    BuildConfig {
        fit_queries: 0,
        ..BuildConfig::default()
    }
}

/// [`compile::db_size`] of a build of the 60 x 40 room.
fn size_of_build(out: &BuildOutput) -> compile::DbSize {
    let links = out.sites.iter().map(|s| s.neighbours.len() as u64).sum();
    compile::db_size(&out.params, 60, 40, out.sites.len(), links)
}

#[test]
fn db_size_is_the_bytes_of_the_sections_it_counts() {
    let out = build(&room(0.05), &quick()).unwrap();
    let counted: usize = out
        .sections
        .iter()
        .filter(|(k, _)| !matches!(k, SectionKind::Index | SectionKind::Manifest))
        .map(|(_, b)| b.len())
        .sum();
    let size = size_of_build(&out);
    assert_eq!(size.total, counted as u64);
    assert_eq!(size.sites, out.sites.len() as u64);
    // 362 beams, a 3,072-cell histogram and the two window widths.
    assert!(size.per_site > 16_000 && size.per_site < 17_000, "{size:?}");
}

#[test]
fn a_database_over_max_db_bytes_is_refused_with_its_size() {
    let src = room(0.05);
    let cfg = quick();
    let out = build(&src, &cfg).unwrap();
    let total = size_of_build(&out).total;
    // Exactly the size passes, one byte less is refused.
    let at = BuildConfig {
        max_db_bytes: total,
        ..cfg.clone()
    };
    assert_eq!(build(&src, &at).unwrap().sections, out.sections);
    let under = BuildConfig {
        max_db_bytes: total - 1,
        ..cfg.clone()
    };
    let e = build(&src, &under).err().unwrap();
    assert!(
        matches!(e, crate::compiler::error::BuildError::TooLarge { total: t, limit, .. } if t == total && limit == total - 1)
    );
    let e = e.to_string();
    assert!(e.contains(&format!("at least {total} bytes")), "{e}");
    assert!(
        e.contains(&format!("the limit is {} bytes (--max-db-bytes", total - 1)),
        "{e}"
    );
    // A resolution far from the map's scale: a site on almost every free
    // cell (about 2,000 sites, 32 MB), refused before their scans are
    // computed.
    let huge = room(100.0);
    let small_limit = BuildConfig {
        max_db_bytes: 10 << 20,
        ..cfg.clone()
    };
    let e = build(&huge, &small_limit).err().unwrap().to_string();
    let free = huge.grid.free_count();
    assert!(
        e.contains(&format!("for {free} free cells at 100 m per cell")),
        "{e}"
    );
    let sites: usize = e
        .split(" reference sites")
        .next()
        .and_then(|t| t.rsplit(' ').next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no site count in: {e}"));
    assert!(sites > free / 2, "{e}");
}
