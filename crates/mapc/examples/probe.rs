// Temporary probe (not shipped).
use mapc::eval::{simulate, ScanSpec};
use mapc::rng::Rng;
use refloc::{localize, scratch_size, Pose2, RangeScan, RefDb, Scan};
fn main() {
    let bytes = std::fs::read("build-artifacts/intel.refdb").unwrap();
    let db = RefDb::new(&bytes[..]).unwrap();
    let a: Vec<f32> = std::env::args().skip(1).map(|s| s.parse().unwrap()).collect();
    let truth = Pose2::new(a[0], a[1], a[2]);
    let swaps = a[3] as usize;
    let spec = ScanSpec { beams: 362, fov: 2.0 * std::f32::consts::PI, range_max: 30.0, noise: 0.005, short_outliers: 0, swap_outliers: swaps.max(1) };
    for seed in 0..40u64 {
    let mut rng = Rng::new(seed);
    let mut s = simulate(&db.grid(), &db.frame(), &truth, &spec, &mut rng);
    if swaps == 0 { s.points = Some(s.ranges.iter().enumerate().map(|(k,&r)| { let an = spec.lidar().angle(k); if r.is_finite() {[r*an.cos(), r*an.sin()]} else {[f32::NAN;2]} }).collect()); }
    let mut scratch = vec![0u8; scratch_size(db.params(), 362)];
    let mut turn = 0.0f32; let mut last: Option<f32> = None;
    for p in s.points.as_ref().unwrap() { if p[0].is_finite() { let an = p[1].atan2(p[0]); if let Some(l) = last { turn += refloc::wrap_angle(an - l); } last = Some(an); } }
    for mode in 0..1 {
        let scan = if mode == 0 { Scan::Points { points: s.points.as_ref().unwrap(), range_max: 30.0 } } else {
            let l = spec.lidar(); Scan::Ranges(RangeScan { angle_min: l.angle_min, angle_increment: l.angle_increment, range_min: 0.0, range_max: 30.0, ranges: &s.ranges }) };
        let l = localize(&db, &scan, &mut scratch).unwrap();
        if l.accepted && (l.pose.x - truth.x).abs() < 0.3 { continue; }
        println!("seed {seed} turn {turn:.3} mode {mode}: pose {:?} acc {} M {:.0}/{:.0} site {} rank {}", l.pose, l.accepted, l.vicinity, l.vicinity_threshold, l.site, l.coarse_rank);
        for c in l.candidates.iter().take(5) { println!("   site {} g {:.3} E {:.1} inl {} pose ({:.2},{:.2},{:.2}) M {:.0}", c.site, c.gamma, c.match_score, c.inliers, c.x, c.y, c.theta, c.vicinity); }
    }
}
}
