use super::*;

fn opts(kind: SynthKind, w: u32, h: u32, seed: u64) -> SynthOptions {
    SynthOptions {
        kind,
        width: w,
        height: h,
        resolution: DEFAULT_RESOLUTION,
        seed,
    }
}

/// Independent BFS check: all free cells form one 4-connected region.
fn free_is_connected(m: &SynthMap) -> bool {
    let (w, h) = (m.width as usize, m.height as usize);
    let Some(start) = m.pixels.iter().position(|&p| p == FREE) else {
        return true;
    };
    let mut seen = vec![false; w * h];
    let mut queue = std::collections::VecDeque::from([start]);
    seen[start] = true;
    let mut n = 0usize;
    while let Some(i) = queue.pop_front() {
        n += 1;
        let (x, y) = (i % w, i / w);
        let mut visit = |j: usize| {
            if !seen[j] && m.pixels[j] == FREE {
                seen[j] = true;
                queue.push_back(j);
            }
        };
        if x > 0 {
            visit(i - 1);
        }
        if x + 1 < w {
            visit(i + 1);
        }
        if y > 0 {
            visit(i - w);
        }
        if y + 1 < h {
            visit(i + w);
        }
    }
    n == m.count(FREE)
}

/// No free cell on the image border or 8-adjacent to an unknown cell.
fn boundary_closed(m: &SynthMap) -> bool {
    let (w, h) = (m.width as usize, m.height as usize);
    for y in 0..h {
        for x in 0..w {
            if m.pixels[y * w + x] != FREE {
                continue;
            }
            if x == 0 || y == 0 || x + 1 == w || y + 1 == h {
                return false;
            }
            for dy in 0..3 {
                for dx in 0..3 {
                    if m.pixels[(y + dy - 1) * w + (x + dx - 1)] == UNKNOWN {
                        return false;
                    }
                }
            }
        }
    }
    true
}

fn check_invariants(m: &SynthMap, o: &SynthOptions) {
    assert_eq!(m.width, o.width);
    assert_eq!(m.height, o.height);
    assert_eq!(m.pixels.len(), o.width as usize * o.height as usize);
    assert!(
        m.pixels
            .iter()
            .all(|&p| p == FREE || p == OCCUPIED || p == UNKNOWN),
        "stray pixel value for {o:?}"
    );
    assert!(free_is_connected(m), "free space not connected for {o:?}");
    assert!(boundary_closed(m), "boundary not closed for {o:?}");
}

/// Free cells over known (non-unknown) cells.
fn free_fraction(m: &SynthMap) -> f64 {
    let known = m.pixels.len() - m.count(UNKNOWN);
    m.count(FREE) as f64 / known.max(1) as f64
}

#[test]
fn kind_parse_and_display_round_trip() {
    for k in SynthKind::ALL {
        assert_eq!(k.to_string().parse::<SynthKind>(), Ok(k));
        assert_eq!(k.as_str().to_uppercase().parse::<SynthKind>(), Ok(k));
    }
    assert_eq!(" cave ".parse::<SynthKind>(), Ok(SynthKind::Cave));
    assert!("forest".parse::<SynthKind>().is_err());
    assert_eq!(SynthKind::Warehouse.to_string(), "warehouse");
}

#[test]
fn command_line_records_options() {
    let mut o = opts(SynthKind::Office, 600, 400, 7);
    assert_eq!(
        o.command_line(),
        "mapc synth --kind office --width 600 --height 400 --resolution 0.05 --seed 7"
    );
    o.resolution = f64::NAN;
    let m = generate(&o);
    assert_eq!(m.resolution, DEFAULT_RESOLUTION);
    assert_eq!(m.options.resolution, DEFAULT_RESOLUTION);
}

#[test]
fn deterministic_per_seed() {
    for k in SynthKind::ALL {
        let a = generate(&opts(k, 300, 220, 11));
        let b = generate(&opts(k, 300, 220, 11));
        let c = generate(&opts(k, 300, 220, 12));
        assert!(a.pixels == b.pixels, "{k}: same seed differs");
        assert!(a.pixels != c.pixels, "{k}: different seeds identical");
    }
    let a = generate(&opts(SynthKind::Office, 600, 400, 3));
    let b = generate(&opts(SynthKind::Office, 600, 400, 3));
    assert!(a == b);
}

#[test]
fn invariants_hold_across_kinds_sizes_and_seeds() {
    let sizes = [
        (64, 64),
        (65, 300),
        (600, 400),
        (400, 600),
        (257, 129),
        (1000, 1000),
    ];
    for k in SynthKind::ALL {
        for (i, &(w, h)) in sizes.iter().enumerate() {
            for seed in 0..3u64 {
                let o = opts(k, w, h, seed * 1000 + i as u64);
                check_invariants(&generate(&o), &o);
            }
        }
    }
}

#[test]
fn odd_resolutions_do_not_panic() {
    for k in SynthKind::ALL {
        for &res in &[
            0.005,
            0.02,
            0.1,
            0.25,
            0.5,
            1.0,
            3.0,
            -1.0,
            0.0,
            f64::INFINITY,
        ] {
            for &(w, h) in &[(64, 64), (200, 90), (90, 200)] {
                let o = SynthOptions {
                    kind: k,
                    width: w,
                    height: h,
                    resolution: res,
                    seed: 5,
                };
                check_invariants(&generate(&o), &o);
            }
        }
    }
}

#[test]
fn random_sizes_and_resolutions_keep_invariants() {
    let mut r = crate::compiler::rng::Rng::new(99);
    for case in 0..90u64 {
        let k = SynthKind::ALL[(case % 3) as usize];
        let o = SynthOptions {
            kind: k,
            width: 64 + r.below(500) as u32,
            height: 64 + r.below(500) as u32,
            resolution: (r.range(-4.6, 0.7)).exp(), // 0.01 .. 2 m/cell
            seed: r.next_u64(),
        };
        check_invariants(&generate(&o), &o);
    }
}

#[test]
fn small_maps_are_walled_boxes() {
    for k in SynthKind::ALL {
        for &(w, h) in &[(0, 0), (0, 10), (1, 1), (2, 5), (3, 3), (10, 63), (63, 200)] {
            let o = opts(k, w, h, 1);
            let m = generate(&o);
            check_invariants(&m, &o);
            let interior = (w.saturating_sub(2) * h.saturating_sub(2)) as usize;
            let expect = if w >= 3 && h >= 3 { interior } else { 0 };
            assert_eq!(m.count(FREE), expect, "{w}x{h}");
            assert_eq!(m.count(UNKNOWN), 0);
        }
    }
}

#[test]
fn free_fraction_in_range_per_kind() {
    let ranges = [
        (SynthKind::Office, 0.6, 0.9),
        (SynthKind::Warehouse, 0.6, 0.9),
        (SynthKind::Cave, 0.22, 0.62),
    ];
    for (k, lo, hi) in ranges {
        for seed in 0..4 {
            for &(w, h) in &[(600, 400), (1000, 1000)] {
                let m = generate(&opts(k, w, h, seed));
                let f = free_fraction(&m);
                assert!(
                    f >= lo && f <= hi,
                    "{k} {w}x{h} seed {seed}: free fraction {f:.3}"
                );
            }
        }
    }
}

#[test]
fn outside_is_unknown_and_wall_is_closed() {
    for k in SynthKind::ALL {
        let m = generate(&opts(k, 600, 400, 9));
        let w = m.width as usize;
        // Image corners lie outside the building.
        for &i in &[0, w - 1, m.pixels.len() - w, m.pixels.len() - 1] {
            assert_eq!(m.pixels[i], UNKNOWN, "{k}");
        }
        assert!(m.count(UNKNOWN) > 0);
    }
}

#[test]
fn layout_loses_little_to_cut_off_pockets() {
    for seed in 0..4 {
        for &(w, h) in &[(600, 400), (1000, 1000)] {
            for k in [SynthKind::Office, SynthKind::Warehouse] {
                let (_, st) = generate_with_stats(&opts(k, w, h, seed));
                let lost = st.removed as f64 / (st.free + st.removed) as f64;
                assert!(lost < 0.02, "{k} {w}x{h} seed {seed}: lost {lost:.4}");
            }
        }
    }
}

#[test]
fn office_room_counts_scale() {
    for seed in 0..6 {
        let (_, demo) = generate_with_stats(&opts(SynthKind::Office, 600, 400, seed));
        assert!(
            (8..=16).contains(&demo.rooms),
            "600x400 seed {seed}: {} rooms",
            demo.rooms
        );
        let (_, big) = generate_with_stats(&opts(SynthKind::Office, 1000, 1000, seed));
        assert!(
            (25..=55).contains(&big.rooms),
            "1000x1000 seed {seed}: {} rooms",
            big.rooms
        );
    }
}

#[test]
fn rooms_differ_between_places() {
    // Crude distinguishability check: the 600x400 office's 80x80-cell tiles
    // (4 m) that hold both free and occupied cells should be nearly all
    // unique.
    for seed in 0..4 {
        let m = generate(&opts(SynthKind::Office, 600, 400, seed));
        let w = m.width as usize;
        let mut tiles = std::collections::HashSet::new();
        let mut n = 0;
        for ty in 0..5 {
            for tx in 0..7 {
                let mut t = Vec::with_capacity(6400);
                for y in 0..80 {
                    let o = (ty * 80 + y) * w + tx * 80;
                    t.extend_from_slice(&m.pixels[o..o + 80]);
                }
                if t.contains(&FREE) && t.contains(&OCCUPIED) {
                    n += 1;
                    tiles.insert(t);
                }
            }
        }
        assert!(
            tiles.len() * 20 >= n * 19,
            "seed {seed}: {} unique of {n}",
            tiles.len()
        );
    }
}

#[test]
fn keep_largest_prefers_biggest_component() {
    // Two free blobs; the hint points at the smaller one.
    let (w, h) = (10, 5);
    let mut px = vec![OCCUPIED; w * h];
    px[w + 1] = FREE;
    for y in 1..4 {
        for x in 4..9 {
            px[y * w + x] = FREE;
        }
    }
    let removed = keep_largest(&mut px, w, h, Some((1, 1)));
    assert_eq!(removed, 1);
    assert_eq!(px[w + 1], OCCUPIED);
    assert_eq!(px.iter().filter(|&&p| p == FREE).count(), 15);
}

fn parse_pgm(bytes: &[u8]) -> (usize, usize, usize, &[u8]) {
    // Header: magic, width, height, maxval as whitespace-separated tokens,
    // then one whitespace byte, then raster.
    let mut pos = 0;
    let mut tokens = Vec::new();
    while tokens.len() < 4 {
        while bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        tokens.push(std::str::from_utf8(&bytes[start..pos]).unwrap().to_string());
    }
    assert_eq!(tokens[0], "P5");
    let w = tokens[1].parse().unwrap();
    let h = tokens[2].parse().unwrap();
    let maxval = tokens[3].parse().unwrap();
    (w, h, maxval, &bytes[pos + 1..])
}

#[test]
fn write_ros_map_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let m = generate(&SynthOptions {
        kind: SynthKind::Warehouse,
        width: 150,
        height: 100,
        resolution: 0.1,
        seed: 42,
    });
    let (yaml, pgm) = write_ros_map(dir.path(), "wh", &m, [-1.5, 2.0, 0.0]).unwrap();
    assert_eq!(yaml, dir.path().join("wh.yaml"));
    assert_eq!(pgm, dir.path().join("wh.pgm"));

    let bytes = std::fs::read(&pgm).unwrap();
    let (w, h, maxval, raster) = parse_pgm(&bytes);
    assert_eq!((w, h, maxval), (150, 100, 255));
    assert_eq!(raster, &m.pixels[..]);

    let img = image::open(&pgm).unwrap().to_luma8();
    assert_eq!(img.dimensions(), (150, 100));
    assert_eq!(img.as_raw(), &m.pixels);

    let text = std::fs::read_to_string(&yaml).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines[0],
        "# generated by: mapc synth --kind warehouse --width 150 --height 100 --resolution 0.1 --seed 42"
    );
    for want in [
        "image: wh.pgm",
        "resolution: 0.1",
        "origin: [-1.5, 2.0, 0.0]",
        "negate: 0",
        "occupied_thresh: 0.65",
        "free_thresh: 0.196",
        "mode: trinary",
    ] {
        assert!(lines.contains(&want), "missing {want:?} in\n{text}");
    }
}

#[test]
fn write_ros_map_rejects_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let m = generate(&opts(SynthKind::Cave, 64, 64, 0));
    assert!(write_ros_map(dir.path(), "", &m, [0.0; 3]).is_err());
    assert!(write_ros_map(dir.path(), "a/b", &m, [0.0; 3]).is_err());
    assert!(write_ros_map(dir.path(), "x", &m, [f64::NAN, 0.0, 0.0]).is_err());
    let mut bad = m.clone();
    bad.pixels.pop();
    assert!(write_ros_map(dir.path(), "x", &bad, [0.0; 3]).is_err());
    // A name needing quotes in YAML still round-trips the image path.
    let (yaml, _) = write_ros_map(dir.path(), "my map", &m, [0.0; 3]).unwrap();
    let text = std::fs::read_to_string(yaml).unwrap();
    assert!(text.contains("image: \"my map.pgm\""));
}

/// Writes sample maps (PGM + YAML + PNG) for eyeballing:
/// `cargo test -p mapc --release synth::tests::render_samples -- --ignored`.
#[test]
#[ignore]
fn render_samples() {
    let dir = std::path::Path::new("/tmp/synth_samples");
    let sizes = [(600, 400), (1000, 1000)];
    for k in SynthKind::ALL {
        for &(w, h) in &sizes {
            for seed in 0..3u64 {
                let o = opts(k, w, h, seed);
                let (m, st) = generate_with_stats(&o);
                let name = format!("{k}_{w}x{h}_s{seed}");
                write_ros_map(dir, &name, &m, [0.0; 3]).unwrap();
                let img = image::GrayImage::from_raw(w, h, m.pixels.clone()).unwrap();
                img.save(dir.join(format!("{name}.png"))).unwrap();
                println!(
                    "{name}: rooms {} free {:.3} removed {}",
                    st.rooms,
                    free_fraction(&m),
                    st.removed
                );
            }
        }
    }
}

/// Times 16000 x 16000 generation:
/// `cargo test -p mapc --release synth::tests::time_16k -- --ignored --nocapture`.
#[test]
#[ignore]
fn time_16k() {
    for k in SynthKind::ALL {
        let o = opts(k, 16000, 16000, 1);
        let t = std::time::Instant::now();
        let (m, st) = generate_with_stats(&o);
        let dt = t.elapsed();
        println!(
            "{k} 16000x16000: {:.2} s, rooms {}, free {:.3}, removed {}",
            dt.as_secs_f64(),
            st.rooms,
            free_fraction(&m),
            st.removed
        );
        assert_eq!(m.pixels.len(), 256_000_000);
        // Downscaled preview (every 16th cell) for eyeballing.
        let (pw, ph) = (1000u32, 1000u32);
        let mut prev = Vec::with_capacity((pw * ph) as usize);
        for y in 0..ph as usize {
            for x in 0..pw as usize {
                prev.push(m.pixels[y * 16 * 16000 + x * 16]);
            }
        }
        let dir = std::path::Path::new("/tmp/synth_samples");
        std::fs::create_dir_all(dir).unwrap();
        image::GrayImage::from_raw(pw, ph, prev)
            .unwrap()
            .save(dir.join(format!("{k}_16k_preview.png")))
            .unwrap();
        // Full-resolution crop (50 m x 50 m) near the middle.
        let mut crop = Vec::with_capacity(1000 * 1000);
        for y in 7500..8500 {
            crop.extend_from_slice(&m.pixels[y * 16000 + 7500..y * 16000 + 8500]);
        }
        image::GrayImage::from_raw(1000, 1000, crop)
            .unwrap()
            .save(dir.join(format!("{k}_16k_crop.png")))
            .unwrap();
    }
}
