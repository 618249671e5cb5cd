//! Runtime parameters: the native, validated form of
//! [`crate::format::ParamsRecord`]. Units: metres, radians.

use crate::format::ParamsRecord;
use zerocopy::little_endian::{F32, U32};
use zerocopy::FromZeros;

/// Most beams a reference scan may have.
pub const MAX_REF_BEAMS: u32 = 4096;
/// Most resampled points per scan.
pub const MAX_POINTS: u32 = 512;
/// Most histogram cells.
pub const MAX_HIST_CELLS: u32 = 4096;
/// Most candidate sites examined by the fine stage.
pub const MAX_CANDIDATES: u32 = 256;
/// Most tentative correspondences per input point.
pub const MAX_TENTATIVE_K: u32 = 16;

/// How the final site is chosen among the candidates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Selection {
    /// Largest matching score E (the paper).
    MatchScore,
    /// Largest vicinity score M (measured improvement).
    Vicinity,
}

/// The sensor that made the reference scans.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorModel {
    /// Beams per scan.
    pub beams: u32,
    /// First beam angle (rad).
    pub angle_min: f32,
    /// Angle step (rad).
    pub angle_increment: f32,
    /// Minimum range (m).
    pub range_min: f32,
    /// Maximum range (m).
    pub range_max: f32,
    /// Mounting pose of the sensor on the robot (m, m, rad).
    pub offset: crate::Pose2,
}

/// A parameter out of its valid range: the field (or group of fields, such
/// as `range_max/range_min`) and the value found, in the field's own unit
/// (for a group, the offending member; for a bin layout, the cell count).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BadParam {
    /// The field's name as the params record spells it.
    pub field: &'static str,
    /// The value found (integers exactly, reals as stored).
    pub value: f64,
}

impl BadParam {
    const fn new(field: &'static str, value: f64) -> BadParam {
        BadParam { field, value }
    }
}

impl core::fmt::Display for BadParam {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{} (found {})", self.field, self.value)
    }
}

/// The first value of `vs` that `ok` refuses, as f64 (NaN if none: the
/// caller checked that one is bad).
fn first_bad(vs: &[f32], ok: impl Fn(f32) -> bool) -> f64 {
    vs.iter()
        .copied()
        .find(|v| !ok(*v))
        .map_or(f64::NAN, |v| v as f64)
}

/// `Ok` when `ok`, else the bad `field` with the `value` found.
fn require(ok: bool, field: &'static str, value: impl Into<f64>) -> Result<(), BadParam> {
    if ok {
        Ok(())
    } else {
        Err(BadParam::new(field, value.into()))
    }
}

/// Finite and positive.
fn pos(v: f32) -> bool {
    v.is_finite() && v > 0.0
}

/// Finite.
fn fin(v: f32) -> bool {
    v.is_finite()
}

/// A share: in `[0, 1]` (not NaN).
fn share(v: f32) -> bool {
    (0.0..=1.0).contains(&v)
}

/// All runtime parameters, one group per pipeline stage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// Reference sensor model.
    pub sensor: SensorModel,
    /// Scan preparation ([`crate::prep`]).
    pub prep: PrepParams,
    /// Coarse stage: PGR histograms, window histograms and the candidate
    /// rule ([`crate::pgr`], [`crate::coarse`]).
    pub coarse: CoarseParams,
    /// Fine stage: scan-to-scan matching ([`crate::ssm`]).
    pub ssm: SsmParams,
    /// Refinement of a matched pose against the map ([`crate::refine`]).
    pub refine: RefineParams,
    /// Verification of a pose against the map ([`crate::verify`]).
    pub verify: VerifyParams,
    /// Choice of the final site among the candidates ([`crate::select`]).
    pub select: SelectParams,
}

/// Scan preparation: resampling and validity of an input scan.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrepParams {
    /// Resampling spacing along surfaces (m).
    pub resample_spacing: f32,
    /// Most resampled points per scan (count).
    pub max_points: u32,
    /// Depth-jump distance between neighbouring points (m).
    pub jump_distance: f32,
    /// Fewest valid points in an input scan (count).
    pub min_valid_points: u32,
}

/// Coarse stage: histogram binning, the stored window histograms for
/// partial fields of view and the candidate-count rule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoarseParams {
    /// Histogram rho bins (count).
    pub hist_rho_bins: u32,
    /// Histogram theta bins (count).
    pub hist_theta_bins: u32,
    /// Histogram rho upper bound (m).
    pub hist_rho_max: f32,
    /// Fewest candidates (count).
    pub nc_min: u32,
    /// Most candidates (count).
    pub nc_max: u32,
    /// Correlation margin below the best for candidates (correlation, 0-1).
    pub nc_margin: f32,
    /// Widths (rad) of the stored window histograms for partial fields of
    /// view; 0 marks an unused slot.
    pub win_widths: [f32; 2],
    /// Headings per window width, evenly spaced from 0 (count).
    pub win_headings: u32,
    /// Window histogram rho bins (count).
    pub win_rho_bins: u32,
    /// Window histogram theta bins (count).
    pub win_theta_bins: u32,
}

/// Fine stage: descriptors, the affinity matrix, its leading eigenvector
/// and the RANSAC pose estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SsmParams {
    /// Descriptor radius (m).
    pub desc_radius: f32,
    /// Tentative correspondences per input point (count).
    pub tentative_k: u32,
    /// Largest rho deviation with non-zero affinity (m).
    pub max_rho_dev: f32,
    /// Logistic weights (bias, 1/m^2, 1/rad^2).
    pub w: [f32; 3],
    /// Power iterations (count).
    pub power_iters: u32,
    /// Binarization fraction (share of the largest eigenvector entry).
    pub binarize_frac: f32,
    /// RANSAC iterations (count).
    pub ransac_iters: u32,
    /// RANSAC inlier distance (m).
    pub ransac_threshold: f32,
    /// RANSAC seed.
    pub ransac_seed: u32,
    /// Fewest inliers (count).
    pub min_inliers: u32,
    /// Most stored affinity entries per SSM match (count; 8 bytes each of
    /// scratch).
    pub affinity_cap: u32,
}

/// Refinement of a matched pose against the map's distance field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefineParams {
    /// Refinement iterations (count; 0: off).
    pub refine_iters: u32,
    /// Refinement cut-off distance (m).
    pub refine_max_dist: f32,
}

/// Verification: the vicinity score and the free-space check.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VerifyParams {
    /// Vicinity sigma_d (m).
    pub sigma_d: f32,
    /// Acceptance ratio (share; paper 0.5).
    pub accept_ratio: f32,
    /// Free-space check: most beams through a wall, as a share of the beams
    /// with a return, for a pose to be accepted (see [`crate::verify`]; 0: off).
    pub through_max: f32,
    /// Free-space check: least excess range (m) of a beam through a wall.
    pub through_excess: f32,
    /// Weight of a short beam against the pose, as a share of a hit's (see
    /// [`crate::verify::Vicinity::evidence`]; 0: the paper's M).
    pub short_weight: f32,
    /// Free-space check: beams through a wall count only in runs of at
    /// least this many consecutive beams (count; 0 or 1: every one counts).
    pub through_run: u32,
    /// Short beams cost nothing when the other beams fit the map at least
    /// this well (explained share; see [`crate::verify::Vicinity::evidence`];
    /// 0: they always cost `short_weight`).
    pub occlusion_fit: f32,
}

/// Selection of the final site among the candidates, early stop and
/// ambiguity rejection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SelectParams {
    /// Site selection rule.
    pub selection: Selection,
    /// Early stop ratio for vicinity selection (share; 0: examine every
    /// candidate).
    pub early_accept: f32,
    /// Stop after this many candidates once one passes the acceptance
    /// threshold (count; 0: never).
    pub early_min: u32,
    /// Ambiguity rejection ratio (share of the best M; 0: off).
    pub ambiguity_ratio: f32,
}

impl SensorModel {
    /// Checks ranges: 3 to [`MAX_REF_BEAMS`] beams over at most a full
    /// turn, `0 <= range_min < range_max` (m), a finite offset.
    pub fn validate(&self) -> Result<(), BadParam> {
        let s = self;
        require(s.beams >= 3 && s.beams <= MAX_REF_BEAMS, "beams", s.beams)?;
        // A finite increment times at most MAX_REF_BEAMS is finite.
        require(
            fin(s.angle_min)
                && pos(s.angle_increment)
                && s.angle_increment * s.beams as f32 <= core::f32::consts::TAU * 1.0001,
            "angle_increment",
            if fin(s.angle_min) {
                s.angle_increment
            } else {
                s.angle_min
            },
        )?;
        // `range_min >= 0.0` is false for NaN.
        require(
            pos(s.range_max) && s.range_min >= 0.0 && s.range_min < s.range_max,
            "range_max/range_min",
            if pos(s.range_max) {
                s.range_min
            } else {
                s.range_max
            },
        )?;
        let offset = [s.offset.x, s.offset.y, s.offset.theta];
        require(
            offset.iter().all(|v| fin(*v)),
            "sensor offset",
            first_bad(&offset, fin),
        )
    }

    fn read_record(r: &ParamsRecord) -> SensorModel {
        SensorModel {
            beams: r.beams.get(),
            angle_min: r.angle_min.get(),
            angle_increment: r.angle_increment.get(),
            range_min: r.range_min.get(),
            range_max: r.range_max.get(),
            offset: crate::Pose2 {
                x: r.sensor_x.get(),
                y: r.sensor_y.get(),
                theta: r.sensor_theta.get(),
            },
        }
    }

    fn write_record(&self, r: &mut ParamsRecord) {
        r.beams = U32::new(self.beams);
        r.angle_min = F32::new(self.angle_min);
        r.angle_increment = F32::new(self.angle_increment);
        r.range_max = F32::new(self.range_max);
        r.range_min = F32::new(self.range_min);
        r.sensor_x = F32::new(self.offset.x);
        r.sensor_y = F32::new(self.offset.y);
        r.sensor_theta = F32::new(self.offset.theta);
    }
}

impl PrepParams {
    /// Checks ranges: positive spacing and jump distance (m), 8 to
    /// [`MAX_POINTS`] points, at least 3 valid points.
    pub fn validate(&self) -> Result<(), BadParam> {
        require(
            pos(self.resample_spacing),
            "resample_spacing",
            self.resample_spacing,
        )?;
        require(
            self.max_points >= 8 && self.max_points <= MAX_POINTS,
            "max_points",
            self.max_points,
        )?;
        require(pos(self.jump_distance), "jump_distance", self.jump_distance)?;
        require(
            self.min_valid_points >= 3,
            "min_valid_points",
            self.min_valid_points,
        )
    }

    fn read_record(r: &ParamsRecord) -> PrepParams {
        PrepParams {
            resample_spacing: r.resample_spacing.get(),
            max_points: r.max_points.get(),
            jump_distance: r.jump_distance.get(),
            min_valid_points: r.min_valid_points.get(),
        }
    }

    fn write_record(&self, r: &mut ParamsRecord) {
        r.resample_spacing = F32::new(self.resample_spacing);
        r.max_points = U32::new(self.max_points);
        r.jump_distance = F32::new(self.jump_distance);
        r.min_valid_points = U32::new(self.min_valid_points);
    }
}

impl CoarseParams {
    /// Number of cells of a PGR histogram (count).
    pub fn hist_cells(&self) -> usize {
        self.hist_rho_bins as usize * self.hist_theta_bins as usize
    }

    /// Cells of a window histogram (count).
    pub fn win_cells(&self) -> usize {
        // Unused when no width is stored; bounded by validate() otherwise.
        if self.win_count() == 0 {
            return 0;
        }
        (self.win_rho_bins as usize).saturating_mul(self.win_theta_bins as usize)
    }

    /// Number of used window widths (the used slots come first).
    pub fn win_count(&self) -> usize {
        self.win_widths.iter().take_while(|w| **w > 0.0).count()
    }

    /// Checks ranges: histogram layouts of at most [`MAX_HIST_CELLS`] cells,
    /// a positive `hist_rho_max` (m), `1 <= nc_min <= nc_max <=`
    /// [`MAX_CANDIDATES`], ascending window widths in `(0, 2 pi)` rad.
    pub fn validate(&self) -> Result<(), BadParam> {
        let (rho, theta) = (self.hist_rho_bins, self.hist_theta_bins);
        require(
            rho != 0 && theta != 0 && rho as u64 * theta as u64 <= MAX_HIST_CELLS as u64,
            "histogram bins",
            rho as f64 * theta as f64,
        )?;
        require(pos(self.hist_rho_max), "hist_rho_max", self.hist_rho_max)?;
        require(
            self.nc_min != 0 && self.nc_max >= self.nc_min && self.nc_max <= MAX_CANDIDATES,
            "nc_min/nc_max",
            if self.nc_min == 0 { 0 } else { self.nc_max },
        )?;
        require(
            fin(self.nc_margin) && self.nc_margin >= 0.0,
            "nc_margin",
            self.nc_margin,
        )?;
        self.validate_windows()
    }

    /// The window histogram part of [`CoarseParams::validate`].
    fn validate_windows(&self) -> Result<(), BadParam> {
        let two_pi = 2.0 * core::f32::consts::PI;
        let width_ok = |w: f32| w == 0.0 || (w.is_finite() && w > 0.0 && w < two_pi);
        let ws = &self.win_widths;
        require(
            ws.iter().all(|w| width_ok(*w)),
            "win_widths",
            first_bad(ws, width_ok),
        )?;
        // An unused slot before a used one, or two widths not ascending.
        let misordered = ws[0] == 0.0 && ws[1] != 0.0 || (self.win_count() == 2 && ws[1] <= ws[0]);
        require(!misordered, "win_widths order", ws[1])?;
        let headings_bad = self.win_headings == 0 || self.win_headings > 64;
        let (rho, theta) = (self.win_rho_bins, self.win_theta_bins);
        let bad_layout = self.win_count() > 0
            && (headings_bad
                || rho == 0
                || theta == 0
                || rho as u64 * theta as u64 > MAX_HIST_CELLS as u64);
        require(
            !bad_layout,
            "window histogram layout",
            if headings_bad {
                self.win_headings as f64
            } else {
                rho as f64 * theta as f64
            },
        )
    }

    fn read_record(r: &ParamsRecord) -> CoarseParams {
        CoarseParams {
            hist_rho_bins: r.hist_rho_bins.get(),
            hist_theta_bins: r.hist_theta_bins.get(),
            hist_rho_max: r.hist_rho_max.get(),
            nc_min: r.nc_min.get(),
            nc_max: r.nc_max.get(),
            nc_margin: r.nc_margin.get(),
            win_widths: r.win_widths.map(|w| w.get()),
            win_headings: r.win_headings.get(),
            win_rho_bins: r.win_rho_bins.get(),
            win_theta_bins: r.win_theta_bins.get(),
        }
    }

    fn write_record(&self, r: &mut ParamsRecord) {
        r.hist_rho_bins = U32::new(self.hist_rho_bins);
        r.hist_theta_bins = U32::new(self.hist_theta_bins);
        r.hist_rho_max = F32::new(self.hist_rho_max);
        r.nc_min = U32::new(self.nc_min);
        r.nc_max = U32::new(self.nc_max);
        r.nc_margin = F32::new(self.nc_margin);
        r.win_widths = self.win_widths.map(F32::new);
        r.win_headings = U32::new(self.win_headings);
        r.win_rho_bins = U32::new(self.win_rho_bins);
        r.win_theta_bins = U32::new(self.win_theta_bins);
    }
}

impl SsmParams {
    /// Checks ranges: positive radii and distances (m), 1 to
    /// [`MAX_TENTATIVE_K`] correspondences, finite weights, bounded
    /// iteration counts, at least 2 inliers, 64 to 2^20 affinity entries.
    pub fn validate(&self) -> Result<(), BadParam> {
        require(pos(self.desc_radius), "desc_radius", self.desc_radius)?;
        require(
            self.tentative_k != 0 && self.tentative_k <= MAX_TENTATIVE_K,
            "tentative_k",
            self.tentative_k,
        )?;
        require(pos(self.max_rho_dev), "max_rho_dev", self.max_rho_dev)?;
        require(self.w.iter().all(|v| fin(*v)), "w", first_bad(&self.w, fin))?;
        require(
            self.power_iters != 0 && self.power_iters <= 1000,
            "power_iters",
            self.power_iters,
        )?;
        require(
            self.binarize_frac >= 0.0 && self.binarize_frac < 1.0,
            "binarize_frac",
            self.binarize_frac,
        )?;
        require(
            self.ransac_iters != 0 && self.ransac_iters <= 100_000,
            "ransac_iters",
            self.ransac_iters,
        )?;
        require(
            pos(self.ransac_threshold),
            "ransac_threshold",
            self.ransac_threshold,
        )?;
        require(self.min_inliers >= 2, "min_inliers", self.min_inliers)?;
        require(
            self.affinity_cap >= 64 && self.affinity_cap <= 1 << 20,
            "affinity_cap",
            self.affinity_cap,
        )
    }

    fn read_record(r: &ParamsRecord) -> SsmParams {
        SsmParams {
            desc_radius: r.desc_radius.get(),
            tentative_k: r.tentative_k.get(),
            max_rho_dev: r.max_rho_dev.get(),
            w: r.w.map(|w| w.get()),
            power_iters: r.power_iters.get(),
            binarize_frac: r.binarize_frac.get(),
            ransac_iters: r.ransac_iters.get(),
            ransac_threshold: r.ransac_threshold.get(),
            ransac_seed: r.ransac_seed.get(),
            min_inliers: r.min_inliers.get(),
            affinity_cap: r.affinity_cap.get(),
        }
    }

    fn write_record(&self, r: &mut ParamsRecord) {
        r.desc_radius = F32::new(self.desc_radius);
        r.tentative_k = U32::new(self.tentative_k);
        r.max_rho_dev = F32::new(self.max_rho_dev);
        r.w = self.w.map(F32::new);
        r.power_iters = U32::new(self.power_iters);
        r.binarize_frac = F32::new(self.binarize_frac);
        r.ransac_iters = U32::new(self.ransac_iters);
        r.ransac_threshold = F32::new(self.ransac_threshold);
        r.ransac_seed = U32::new(self.ransac_seed);
        r.min_inliers = U32::new(self.min_inliers);
        r.affinity_cap = U32::new(self.affinity_cap);
    }
}

impl RefineParams {
    /// Checks ranges: at most 1000 iterations, a positive cut-off (m).
    pub fn validate(&self) -> Result<(), BadParam> {
        require(
            self.refine_iters <= 1000 && pos(self.refine_max_dist),
            "refine",
            if self.refine_iters > 1000 {
                self.refine_iters as f64
            } else {
                self.refine_max_dist as f64
            },
        )
    }

    fn read_record(r: &ParamsRecord) -> RefineParams {
        RefineParams {
            refine_iters: r.refine_iters.get(),
            refine_max_dist: r.refine_max_dist.get(),
        }
    }

    fn write_record(&self, r: &mut ParamsRecord) {
        r.refine_iters = U32::new(self.refine_iters);
        r.refine_max_dist = F32::new(self.refine_max_dist);
    }
}

impl VerifyParams {
    /// Checks ranges: a positive `sigma_d` (m), shares in `[0, 1]`, a
    /// finite non-negative `through_excess` (m), runs of at most 64 beams.
    pub fn validate(&self) -> Result<(), BadParam> {
        require(pos(self.sigma_d), "sigma_d", self.sigma_d)?;
        require(share(self.accept_ratio), "accept_ratio", self.accept_ratio)?;
        require(share(self.through_max), "through_max", self.through_max)?;
        require(
            fin(self.through_excess) && self.through_excess >= 0.0,
            "through_excess",
            self.through_excess,
        )?;
        require(share(self.short_weight), "short_weight", self.short_weight)?;
        require(self.through_run <= 64, "through_run", self.through_run)?;
        require(
            share(self.occlusion_fit),
            "occlusion_fit",
            self.occlusion_fit,
        )
    }

    fn read_record(r: &ParamsRecord) -> VerifyParams {
        VerifyParams {
            sigma_d: r.sigma_d.get(),
            accept_ratio: r.accept_ratio.get(),
            through_max: r.through_max.get(),
            through_excess: r.through_excess.get(),
            short_weight: r.short_weight.get(),
            through_run: r.through_run.get(),
            occlusion_fit: r.occlusion_fit.get(),
        }
    }

    fn write_record(&self, r: &mut ParamsRecord) {
        r.sigma_d = F32::new(self.sigma_d);
        r.accept_ratio = F32::new(self.accept_ratio);
        r.through_max = F32::new(self.through_max);
        r.through_excess = F32::new(self.through_excess);
        r.short_weight = F32::new(self.short_weight);
        r.through_run = U32::new(self.through_run);
        r.occlusion_fit = F32::new(self.occlusion_fit);
    }
}

impl SelectParams {
    /// Checks ranges: `ambiguity_ratio` and `early_accept` are shares in
    /// `[0, 1]` (the rule itself was checked when the record was read).
    pub fn validate(&self) -> Result<(), BadParam> {
        require(
            share(self.ambiguity_ratio),
            "ambiguity_ratio",
            self.ambiguity_ratio,
        )?;
        require(share(self.early_accept), "early_accept", self.early_accept)
    }

    /// Reads the group; an unknown selection code is a bad `selection`.
    fn read_record(r: &ParamsRecord) -> Result<SelectParams, BadParam> {
        Ok(SelectParams {
            selection: match r.selection.get() {
                0 => Selection::MatchScore,
                1 => Selection::Vicinity,
                v => return Err(BadParam::new("selection", v as f64)),
            },
            early_accept: r.early_accept.get(),
            early_min: r.early_min.get(),
            ambiguity_ratio: r.ambiguity_ratio.get(),
        })
    }

    fn write_record(&self, r: &mut ParamsRecord) {
        r.selection = U32::new(match self.selection {
            Selection::MatchScore => 0,
            Selection::Vicinity => 1,
        });
        r.early_accept = F32::new(self.early_accept);
        r.early_min = U32::new(self.early_min);
        r.ambiguity_ratio = F32::new(self.ambiguity_ratio);
    }
}

impl Params {
    /// The defaults for a reference sensor of `beams` beams over 360 degrees
    /// and `range_max` metres.
    pub fn defaults(beams: u32, range_max: f32) -> Params {
        let inc = 2.0 * core::f32::consts::PI / beams.max(1) as f32;
        Params {
            sensor: SensorModel {
                beams,
                angle_min: -core::f32::consts::PI,
                angle_increment: inc,
                range_min: 0.0,
                range_max,
                offset: crate::Pose2::default(),
            },
            prep: PrepParams {
                resample_spacing: 0.10,
                max_points: 160,
                jump_distance: 0.30,
                min_valid_points: 20,
            },
            coarse: CoarseParams {
                hist_rho_bins: 32,
                hist_theta_bins: 18,
                hist_rho_max: 16.0,
                nc_min: 5,
                nc_max: 80,
                nc_margin: 0.25,
                win_widths: [core::f32::consts::PI, 1.5 * core::f32::consts::PI],
                win_headings: 8,
                win_rho_bins: 16,
                win_theta_bins: 12,
            },
            ssm: SsmParams {
                desc_radius: 2.0,
                tentative_k: 2,
                max_rho_dev: 0.3,
                w: [4.0, -100.0, -20.0],
                // 15, not the 30 it was until 2026-12-06: chosen on the
                // real Intel and ACES logs (10, 15, 20, 30 tried: 15 had
                // the most right answers at the same false accepts), checked
                // on CSAIL, the simulated experiments and the wrong-map
                // check (docs/performance.md, "Fewer power iterations").
                power_iters: 15,
                binarize_frac: 0.05,
                ransac_iters: 64,
                ransac_threshold: 0.2,
                ransac_seed: 0x5EED,
                min_inliers: 6,
                affinity_cap: crate::localize::AFFINITY_CAP as u32,
            },
            refine: RefineParams {
                refine_iters: 10,
                refine_max_dist: 0.3,
            },
            verify: VerifyParams {
                sigma_d: 0.05,
                accept_ratio: 0.5,
                through_max: 0.01,
                through_excess: 0.5,
                short_weight: 1.0,
                through_run: 3,
                occlusion_fit: 0.9,
            },
            select: SelectParams {
                selection: Selection::Vicinity,
                early_accept: 0.9,
                early_min: 0,
                ambiguity_ratio: 0.97,
            },
        }
    }

    /// Checks ranges group by group (sensor, prep, coarse, ssm, refine,
    /// verify, select); returns the first bad field with the value found.
    pub fn validate(&self) -> Result<(), BadParam> {
        self.sensor.validate()?;
        self.prep.validate()?;
        self.coarse.validate()?;
        self.ssm.validate()?;
        self.refine.validate()?;
        self.verify.validate()?;
        self.select.validate()
    }

    /// Reads a record (no range checks; call [`Params::validate`]). Fails
    /// only on an unknown selection code.
    pub fn from_record(r: &ParamsRecord) -> Result<Params, BadParam> {
        Ok(Params {
            sensor: SensorModel::read_record(r),
            prep: PrepParams::read_record(r),
            coarse: CoarseParams::read_record(r),
            ssm: SsmParams::read_record(r),
            refine: RefineParams::read_record(r),
            verify: VerifyParams::read_record(r),
            select: SelectParams::read_record(r)?,
        })
    }

    /// The on-disk record: every group writes its own fields.
    pub fn to_record(&self) -> ParamsRecord {
        let mut r = ParamsRecord::new_zeroed();
        self.sensor.write_record(&mut r);
        self.prep.write_record(&mut r);
        self.coarse.write_record(&mut r);
        self.ssm.write_record(&mut r);
        self.refine.write_record(&mut r);
        self.verify.write_record(&mut r);
        self.select.write_record(&mut r);
        r
    }
}
