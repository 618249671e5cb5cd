// Temporary profiling harness (not shipped).
use mapc::eval::{sample_poses, simulate, ScanSpec};
use mapc::rng::Rng;
use refloc::{localize, scratch_size, RangeScan, RefDb, Scan};
fn main() {
    let bytes = std::fs::read("build-artifacts/intel.refdb").unwrap();
    let mut al = vec![0u32; bytes.len() / 4 + 1];
    let ab: &mut [u8] = zerocopy::IntoBytes::as_mut_bytes(&mut al[..]);
    ab[..bytes.len()].copy_from_slice(&bytes);
    let db = RefDb::new(&ab[..bytes.len()]).unwrap();
    let poses = sample_poses(&db, 100, 0.3, 3);
    let spec = ScanSpec { beams: 362, fov: 2.0 * std::f32::consts::PI, range_max: 30.0, noise: 0.0, short_outliers: 0, swap_outliers: 0 };
    let l = spec.lidar();
    let mut scratch = vec![0u8; scratch_size(db.params(), 362)];
    let scans: Vec<Vec<f32>> = poses.iter().map(|p| simulate(&db.grid(), &db.frame(), p, &spec, &mut Rng::new(1)).ranges).collect();
    let t = std::time::Instant::now();
    let mut nc = 0;
    for r in &scans {
        let s = Scan::Ranges(RangeScan { angle_min: l.angle_min, angle_increment: l.angle_increment, range_min: 0.0, range_max: 30.0, ranges: r });
        let x = localize(&db, &s, &mut scratch).unwrap();
        nc += x.candidates.len();
    }
    println!("{:.2} ms/query, {:.1} candidates avg", t.elapsed().as_secs_f64() * 1000.0 / scans.len() as f64, nc as f64 / scans.len() as f64);
}
