// Temporary experiment harness (not shipped).
use mapc::compile::{compile, CompileInput, SiteIn};
use mapc::rng::Rng;
use mapc::sim::{self, Lidar, Noise};
use refloc::params::Params;
use refloc::raycast::BitGrid;
use refloc::{localize, scratch_size, MapFrame, Pose2, RangeScan, RefDb, Scan};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(200);
    let dynamic = args.get(2).map(|s| s == "dyn").unwrap_or(false);
    let img = image::open("/work/shared/maps/intel/intel.pgm").unwrap().to_luma8();
    let (w, h) = img.dimensions();
    let res = 0.05f32;
    // cells: cy=0 bottom
    let mut blocked = vec![0u32; BitGrid::words_for(w, h)];
    let mut free = vec![false; (w * h) as usize];
    for cy in 0..h {
        for cx in 0..w {
            let v = img.get_pixel(cx, h - 1 - cy)[0];
            let i = (cy * w + cx) as usize;
            if v >= 250 { free[i] = true; } else { blocked[i / 32] |= 1 << (i % 32); }
        }
    }
    // brute-ish sq dist via BFS-free naive: use a simple two-pass chamfer approx for experiment
    let mut d = vec![1e9f32; (w * h) as usize];
    let idx = |x: i64, y: i64| (y * w as i64 + x) as usize;
    for i in 0..d.len() { if !free[i] { d[i] = 0.0; } }
    // exact-ish via per-row/col FH would be better; here approximate euclid with 8-neighbour chamfer (3x passes)
    for _ in 0..2 {
        for y in 0..h as i64 { for x in 0..w as i64 {
            let mut v = d[idx(x,y)];
            for (dx,dy,c) in [(-1,0,1.0),(0,-1,1.0),(-1,-1,1.4142),(1,-1,1.4142)] {
                let (nx,ny)=(x+dx,y+dy); if nx>=0&&ny>=0&&nx<w as i64&&ny<h as i64 { v=v.min(d[idx(nx,ny)]+c);} }
            d[idx(x,y)]=v; }}
        for y in (0..h as i64).rev() { for x in (0..w as i64).rev() {
            let mut v = d[idx(x,y)];
            for (dx,dy,c) in [(1,0,1.0),(0,1,1.0),(1,1,1.4142),(-1,1,1.4142)] {
                let (nx,ny)=(x+dx,y+dy); if nx>=0&&ny>=0&&nx<w as i64&&ny<h as i64 { v=v.min(d[idx(nx,ny)]+c);} }
            d[idx(x,y)]=v; }}
    }
    let sq: Vec<f32> = d.iter().map(|v| v * v).collect();
    let frame = MapFrame { resolution: res, origin: Pose2::new(0.0, 0.0, 0.0) };
    let mut sites = Vec::new();
    let step = (2.0 / res) as u32;
    for cy in (0..h).step_by(step as usize) { for cx in (0..w).step_by(step as usize) {
        let i = (cy * w + cx) as usize;
        if free[i] && d[i] * res >= 0.4 {
            sites.push(SiteIn { x: (cx as f64 + 0.5) * res as f64, y: (cy as f64 + 0.5) * res as f64, clearance: (d[i] * res) as f64, kind: 2, neighbours: vec![] });
        }
    }}
    let params = Params::defaults(362, 30.0);
    let t = std::time::Instant::now();
    let input = CompileInput { width: w, height: h, frame, blocked: &blocked, sq_dist: &sq, unknown_blocks: true, free_cells: 0, params, fit_queries: 60, fit_seed: 1 };
    let c = compile(&input, &sites).unwrap();
    eprintln!("sites {} compile {:?} fit {:?}", sites.len(), t.elapsed(), c.fit);
    let mut secs: Vec<(refloc::format::SectionKind, &[u8])> = c.sections.iter().map(|(k, b)| (*k, b.as_slice())).collect(); secs.push((refloc::format::SectionKind::Manifest, b"{}"));
    let mut bytes = Vec::new();
    refloc::format::encode(&secs, |b| { bytes.extend_from_slice(b); Ok::<(), ()>(()) }).unwrap();
    // realign
    let mut al = vec![0u32; bytes.len() / 4 + 1];
    let ab: &mut [u8] = zerocopy::IntoBytes::as_mut_bytes(&mut al[..]);
    ab[..bytes.len()].copy_from_slice(&bytes);
    let db = RefDb::new(&ab[..bytes.len()]).unwrap();
    db.verify().unwrap();
    let grid = db.grid();
    let lidar = Lidar::new(362, 2.0 * std::f32::consts::PI, 30.0);
    let mut scratch = vec![0u8; scratch_size(db.params(), 362)];
    eprintln!("scratch {} bytes", scratch.len());
    let mut rng = Rng::new(7);
    let (mut ok, mut acc, mut correct, mut tried) = (0, 0, 0, 0);
    let mut ex = 0.0; let mut ey = 0.0; let mut et = 0.0;
    let t = std::time::Instant::now();
    let mut ranks: Vec<usize> = Vec::new();
    while tried < n {
        let cx = rng.below(w as u64) as usize; let cy = rng.below(h as u64) as usize;
        let i = cy * w as usize + cx;
        if !free[i] || d[i] * res < 0.3 { continue; }
        tried += 1;
        let truth = Pose2::new((cx as f32 + 0.5) * res, (cy as f32 + 0.5) * res, rng.range(-3.14159, 3.14159) as f32);
        let mut ranges = sim::virtual_scan(&grid, &frame, &truth, &lidar);
        if dynamic { sim::add_noise(&mut ranges, &lidar, &Noise { range_sigma: 0.005, short_outliers: 60 }, &mut rng); }
        let scan = Scan::Ranges(RangeScan { angle_min: lidar.angle_min, angle_increment: lidar.angle_increment, range_min: 0.0, range_max: 30.0, ranges: &ranges });
        match localize(&db, &scan, &mut scratch) {
            Ok(l) => {
                ok += 1;
                let e = ((l.pose.x - truth.x).powi(2) + (l.pose.y - truth.y).powi(2)).sqrt();
                let eth = refloc::wrap_angle(l.pose.theta - truth.theta).abs();
                let good = e < 0.3 && eth < 5f32.to_radians();
                if l.accepted { acc += 1; if good { correct += 1; ex += (l.pose.x - truth.x).abs(); ey += (l.pose.y - truth.y).abs(); et += eth; } }
                // correct site: nearest with line of sight
                let tuv = frame.to_cells([truth.x, truth.y]);
                let mut bestd = f32::INFINITY; let mut cs = usize::MAX;
                for si in 0..db.site_count() { let sxy = db.site_xy(si); let dd = ((sxy[0]-truth.x).powi(2)+(sxy[1]-truth.y).powi(2)).sqrt();
                    let ang = (sxy[1]-truth.y).atan2(sxy[0]-truth.x);
                    let hit = refloc::raycast::cast(&grid, tuv[0], tuv[1], ang, dd / res);
                    if hit.is_none() && dd < bestd { bestd = dd; cs = si; } }
                let mut qh = vec![0f32; db.params().hist_cells()];
                { let sc = mapc::compile::scan_histogram(&ranges, db.params()); qh.copy_from_slice(&sc); }
                let gc = if cs != usize::MAX { refloc::coarse::correlation(&qh, db.hist(cs)) } else { -2.0 };
                let rank = (0..db.site_count()).filter(|&s| refloc::coarse::correlation(&qh, db.hist(s)) > gc).count();
                ranks.push(rank);
                if !good || !l.accepted {
                    eprintln!("   correct site {cs} at {bestd:.2} m, coarse rank {rank}");
                    let best_rank = l.candidates.iter().filter(|c| ((c.x-truth.x).powi(2)+(c.y-truth.y).powi(2)).sqrt()<0.3).map(|c| c.rank as i32).min().unwrap_or(-1);
                    eprintln!("miss: truth ({:.2},{:.2},{:.1}) got ({:.2},{:.2}) acc {} M {:.0}/{:.0} nc {} good-cand-rank {}", truth.x, truth.y, truth.theta.to_degrees(), l.pose.x, l.pose.y, l.accepted, l.vicinity, l.vicinity_threshold, l.candidates.len(), best_rank);
                }
            }
            Err(e) => eprintln!("err {e}"),
        }
    }
    let el = t.elapsed();
    ranks.sort(); let nr = ranks.len();
    println!("rank of correct site: p50 {} p90 {} p99 {} max {}; within 10: {:.1}% within 20: {:.1}% within 30: {:.1}%", ranks[nr/2], ranks[nr*9/10], ranks[(nr*99/100).min(nr-1)], ranks[nr-1], 100.0*ranks.iter().filter(|&&r| r<10).count() as f64/nr as f64, 100.0*ranks.iter().filter(|&&r| r<20).count() as f64/nr as f64, 100.0*ranks.iter().filter(|&&r| r<30).count() as f64/nr as f64);
    println!("n {tried} ok {ok} accepted {acc} accepted&correct {correct} ({:.1}%) mean |x| {:.1} mm |y| {:.1} mm th {:.2} deg; {:.1} ms/query", 100.0 * correct as f64 / tried as f64, 1000.0 * ex / correct as f32, 1000.0 * ey / correct as f32, (et / correct as f32).to_degrees(), el.as_secs_f64() * 1000.0 / tried as f64);
}
