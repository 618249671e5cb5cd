use super::*;
use crate::compiler::mapfile::OccupancyGrid;

/// A walled 60 x 40 room with a pillar, at `resolution` m per cell (also
/// the derived-reach tests' map).
pub(crate) fn room(resolution: f64) -> MapSource {
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
fn size_of_build(out: &BuildOutput, features: bool) -> compile::DbSize {
    let links = out.sites.iter().map(|s| s.neighbours.len() as u64).sum();
    compile::db_size(&out.params, 60, 40, out.sites.len(), links, features)
}

/// The bytes of section `k` among `sections` (empty when there is none).
pub(crate) fn section(sections: &[(SectionKind, Vec<u8>)], k: SectionKind) -> &[u8] {
    sections
        .iter()
        .find(|(kind, _)| *kind == k)
        .map_or(&[], |(_, b)| b.as_slice())
}

/// The bytes of a build's section `k` (empty when it has none).
fn section_of(out: &BuildOutput, k: SectionKind) -> &[u8] {
    section(&out.sections, k)
}

#[test]
fn db_size_is_the_bytes_of_the_sections_it_counts() {
    for features in [false, true] {
        let cfg = BuildConfig {
            ssm_features: features,
            ..quick()
        };
        let out = build(&room(0.05), &cfg).unwrap();
        let counted: usize = out
            .sections
            .iter()
            .filter(|(k, _)| !matches!(k, SectionKind::Index | SectionKind::Manifest))
            .map(|(_, b)| b.len())
            .sum();
        let size = size_of_build(&out, features);
        // Exact but for the features section, counted at max_points per site.
        let stored = section_of(&out, SectionKind::Features).len() as u64;
        assert_eq!(size.total - size.features, counted as u64 - stored);
        assert!(stored <= size.features, "{stored} {size:?}");
        assert_eq!(size.sites, out.sites.len() as u64);
        // 362 beams, a 3,072-cell histogram and the two window widths; with
        // the features up to 160 points of 80 bytes and an offset.
        let extra = if features { 4 + 160 * 80 } else { 0 };
        assert!(
            size.per_site > 16_000 + extra && size.per_site < 17_000 + extra,
            "{size:?}"
        );
        assert_eq!(features, stored > 0, "{stored}");
    }
}

#[test]
fn stored_features_are_the_runtimes_and_change_no_answer() {
    let src = room(0.05);
    let with = build(&src, &quick()).unwrap();
    let without = build(
        &src,
        &BuildConfig {
            ssm_features: false,
            ..quick()
        },
    )
    .unwrap();
    // The same sections but the features and the manifest (which records
    // the option).
    let others = |o: &BuildOutput| {
        o.sections
            .iter()
            .filter(|(k, _)| !matches!(k, SectionKind::Features | SectionKind::Manifest))
            .cloned()
            .collect::<Vec<_>>()
    };
    assert_eq!(others(&with), others(&without));
    let (wa, la) = crate::compiler::reach::encode_aligned(&with.sections);
    let (wb, lb) = crate::compiler::reach::encode_aligned(&without.sections);
    let a = refloc::RefDb::new(&zerocopy::IntoBytes::as_bytes(&wa[..])[..la]).unwrap();
    let b = refloc::RefDb::new(&zerocopy::IntoBytes::as_bytes(&wb[..])[..lb]).unwrap();
    a.verify().unwrap();
    // Every site's stored features are what the runtime computes.
    let p = a.params();
    let m = p.prep.max_points as usize;
    for i in 0..a.site_count() {
        let f = a.features(i).expect("stored");
        assert!(b.features(i).is_none());
        let mut dense = vec![[0f32; 2]; p.sensor.beams as usize];
        let (mut pts, mut tan) = (vec![[0f32; 2]; m], vec![[0f32; 2]; m]);
        let mut desc = vec![0u16; m * refloc::ssm::DESC_LEN];
        let n = refloc::localize::reference_features(
            a.scan(i),
            p,
            &mut dense,
            &mut pts,
            &mut tan,
            &mut desc,
        );
        assert!(n >= 8, "site {i}: {n} points");
        assert_eq!(f.points, &pts[..n]);
        assert_eq!(f.tangents, &tan[..n]);
        assert_eq!(f.desc, &desc[..n * refloc::ssm::DESC_LEN]);
    }
    // Scans from a few poses localize to identical answers either way.
    let lidar = compile::ref_lidar(p);
    let grid = a.grid();
    let mut scratch = vec![0u8; refloc::scratch_size(p, lidar.beams)];
    for (k, pose) in [(0.4, 0.5, 0.3), (2.2, 1.1, -2.0), (1.0, 1.5, 1.2)]
        .into_iter()
        .enumerate()
    {
        let pose = refloc::Pose2::new(pose.0, pose.1, pose.2);
        let ranges = crate::compiler::sim::virtual_scan(&grid, &a.frame(), &pose, &lidar);
        let scan = refloc::Scan::Ranges(refloc::RangeScan {
            angle_min: lidar.angle_min,
            angle_increment: lidar.angle_increment,
            range_min: lidar.range_min,
            range_max: lidar.range_max,
            ranges: &ranges,
        });
        let la = format!("{:?}", refloc::localize(&a, &scan, &mut scratch));
        let lb = format!("{:?}", refloc::localize(&b, &scan, &mut scratch));
        assert_eq!(la, lb, "scan {k}");
        assert!(la.starts_with("Ok("), "scan {k}: {la}");
    }
}

#[test]
fn a_database_over_max_db_bytes_is_refused_with_its_size() {
    let src = room(0.05);
    let cfg = quick();
    let out = build(&src, &cfg).unwrap();
    let total = size_of_build(&out, true).total;
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
    assert!(e.contains(&format!("about {total} bytes")), "{e}");
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
