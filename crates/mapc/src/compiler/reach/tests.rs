use super::*;
use crate::compiler::mapfile::MapSource;
use crate::compiler::pipeline::tests::section;
use crate::compiler::pipeline::{build, BuildConfig};

/// The pipeline tests' walled room with a pillar, 6 x 4 m at 0.1 m per
/// cell: from most sites some walls lie beyond a 2.5 m reach.
fn room() -> MapSource {
    crate::compiler::pipeline::tests::room(0.1)
}

#[test]
fn a_derived_reach_is_what_a_build_for_that_reach_stores() {
    let src = room();
    let full = build(&src, &BuildConfig::default()).unwrap();
    let short = build(
        &src,
        &BuildConfig {
            range_max: 2.5,
            ..BuildConfig::default()
        },
    )
    .unwrap();
    let (words, len) = encode_aligned(&full.sections);
    let db = RefDb::new(&zerocopy::IntoBytes::as_bytes(&words[..])[..len]).unwrap();
    let derived = derive_for_reach(&db, 2.5, false).unwrap();
    // The reach shortens the reference scans: some beams lose their return.
    assert_ne!(
        section(&derived, SectionKind::Scans),
        section(&full.sections, SectionKind::Scans)
    );
    // Everything but the parameters (below), the manifest and the index
    // (the room is too small for one) is the build's, byte for byte.
    let skip = [
        SectionKind::Params,
        SectionKind::Manifest,
        SectionKind::Index,
    ];
    for k in SectionKind::ALL.into_iter().filter(|k| !skip.contains(k)) {
        assert_eq!(
            section(&derived, k),
            section(&short.sections, k),
            "section {}",
            k.name()
        );
    }
    let (dw, dl) = encode_aligned(&derived);
    let d = RefDb::new(&zerocopy::IntoBytes::as_bytes(&dw[..])[..dl]).unwrap();
    d.verify().unwrap();
    let mut p = *d.params();
    assert_eq!(p.sensor.range_max, 2.5);
    // The SSM weights are fitted again; their fit reads the clearance from
    // the stored distance map rather than the map's exact one.
    p.ssm.w = short.params.ssm.w;
    assert_eq!(p, short.params);
    assert_eq!(d.decision(), db.decision());
    // Deterministic.
    assert_eq!(derive_for_reach(&db, 2.5, false).unwrap(), derived);
    // With the full search only the early stops' parameters change.
    let full = derive_for_reach(&db, 2.5, true).unwrap();
    let (fw, fl) = encode_aligned(&full);
    let f = RefDb::new(&zerocopy::IntoBytes::as_bytes(&fw[..])[..fl]).unwrap();
    let mut q = *f.params();
    assert_eq!((q.select.early_accept, q.select.early_min), (0.0, 0));
    q.select.early_accept = d.params().select.early_accept;
    q.select.early_min = d.params().select.early_min;
    assert_eq!(q, *d.params());
    for k in [
        SectionKind::Scans,
        SectionKind::Hists,
        SectionKind::Windows,
        SectionKind::Features,
    ] {
        assert_eq!(section(&full, k), section(&derived, k));
    }
}

#[test]
fn a_reach_not_under_the_databases_own_is_refused() {
    let src = room();
    let full = build(&src, &BuildConfig::default()).unwrap();
    let (words, len) = encode_aligned(&full.sections);
    let db = RefDb::new(&zerocopy::IntoBytes::as_bytes(&words[..])[..len]).unwrap();
    for r in [0.0, -1.0, f32::NAN, f32::INFINITY, 30.0, 45.0] {
        match derive_for_reach(&db, r, true) {
            Err(BuildError::Option(b)) => assert_eq!(b.field, "range_max"),
            other => panic!("{r}: {:?}", other.map(|s| s.len())),
        }
    }
}
