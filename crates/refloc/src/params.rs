//! Runtime parameters: the native, validated form of
//! [`crate::format::ParamsRecord`]. Units: metres, radians.

use crate::format::ParamsRecord;
use zerocopy::little_endian::{F32, U32};

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

/// All runtime parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// Reference sensor model.
    pub sensor: SensorModel,
    /// Resampling spacing along surfaces (m).
    pub resample_spacing: f32,
    /// Most resampled points per scan.
    pub max_points: u32,
    /// Depth-jump distance between neighbouring points (m).
    pub jump_distance: f32,
    /// Histogram rho bins.
    pub hist_rho_bins: u32,
    /// Histogram theta bins.
    pub hist_theta_bins: u32,
    /// Histogram rho upper bound (m).
    pub hist_rho_max: f32,
    /// Fewest candidates.
    pub nc_min: u32,
    /// Most candidates.
    pub nc_max: u32,
    /// Correlation margin below the best for candidates.
    pub nc_margin: f32,
    /// Descriptor radius (m).
    pub desc_radius: f32,
    /// Tentative correspondences per input point.
    pub tentative_k: u32,
    /// Largest rho deviation with non-zero affinity (m).
    pub max_rho_dev: f32,
    /// Logistic weights (bias, 1/m^2, 1/rad^2).
    pub w: [f32; 3],
    /// Power iterations.
    pub power_iters: u32,
    /// Binarization fraction.
    pub binarize_frac: f32,
    /// RANSAC iterations.
    pub ransac_iters: u32,
    /// RANSAC inlier distance (m).
    pub ransac_threshold: f32,
    /// RANSAC seed.
    pub ransac_seed: u32,
    /// Fewest inliers.
    pub min_inliers: u32,
    /// Refinement iterations (0: off).
    pub refine_iters: u32,
    /// Refinement cut-off distance (m).
    pub refine_max_dist: f32,
    /// Vicinity sigma_d (m).
    pub sigma_d: f32,
    /// Acceptance ratio (paper 0.5).
    pub accept_ratio: f32,
    /// Fewest valid points in an input scan.
    pub min_valid_points: u32,
    /// Site selection rule.
    pub selection: Selection,
    /// Early stop ratio for vicinity selection (0: examine every candidate).
    pub early_accept: f32,
    /// Widths (rad) of the stored window histograms for partial fields of
    /// view; 0 marks an unused slot.
    pub win_widths: [f32; 2],
    /// Headings per window width, evenly spaced from 0.
    pub win_headings: u32,
    /// Window histogram rho bins.
    pub win_rho_bins: u32,
    /// Window histogram theta bins.
    pub win_theta_bins: u32,
    /// Stop after this many candidates once one passes the acceptance threshold (0: never).
    pub early_min: u32,
    /// Ambiguity rejection ratio (0: off).
    pub ambiguity_ratio: f32,
    /// Most stored affinity entries per SSM match (8 bytes each of scratch).
    pub affinity_cap: u32,
    /// Free-space check: most beams through a wall, as a share of the beams
    /// with a return, for a pose to be accepted (see [`crate::verify`]; 0: off).
    pub through_max: f32,
    /// Free-space check: least excess range (m) of a beam through a wall.
    pub through_excess: f32,
    /// Verification: weight of a short beam against the pose, as a share of
    /// a hit's (see [`crate::verify::Vicinity::evidence`]; 0: the paper's M).
    pub short_weight: f32,
    /// Free-space check: beams through a wall count only in runs of at
    /// least this many consecutive beams (0 or 1: every one counts).
    pub through_run: u32,
    /// Verification: short beams cost nothing when the other beams fit the
    /// map at least this well (see [`crate::verify::Vicinity::evidence`]; 0:
    /// they always cost `short_weight`).
    pub occlusion_fit: f32,
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
            resample_spacing: 0.10,
            max_points: 160,
            jump_distance: 0.30,
            hist_rho_bins: 32,
            hist_theta_bins: 18,
            hist_rho_max: 16.0,
            nc_min: 5,
            nc_max: 80,
            nc_margin: 0.25,
            desc_radius: 2.0,
            tentative_k: 2,
            max_rho_dev: 0.3,
            w: [4.0, -100.0, -20.0],
            power_iters: 30,
            binarize_frac: 0.05,
            ransac_iters: 64,
            ransac_threshold: 0.2,
            ransac_seed: 0x5EED,
            min_inliers: 6,
            refine_iters: 10,
            refine_max_dist: 0.3,
            sigma_d: 0.05,
            accept_ratio: 0.5,
            min_valid_points: 20,
            selection: Selection::Vicinity,
            early_accept: 0.9,
            win_widths: [core::f32::consts::PI, 1.5 * core::f32::consts::PI],
            win_headings: 8,
            win_rho_bins: 16,
            win_theta_bins: 12,
            early_min: 0,
            ambiguity_ratio: 0.97,
            affinity_cap: crate::localize::AFFINITY_CAP as u32,
            through_max: 0.01,
            through_excess: 0.5,
            short_weight: 1.0,
            through_run: 3,
            occlusion_fit: 0.9,
        }
    }

    /// Number of cells of a PGR histogram.
    pub fn hist_cells(&self) -> usize {
        self.hist_rho_bins as usize * self.hist_theta_bins as usize
    }

    /// Cells of a window histogram.
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

    /// Checks ranges; returns the first bad field with the value found.
    pub fn validate(&self) -> Result<(), BadParam> {
        let s = &self.sensor;
        let pos = |v: f32| v.is_finite() && v > 0.0;
        let fin = |v: f32| v.is_finite();
        if s.beams < 3 || s.beams > MAX_REF_BEAMS {
            return Err(BadParam::new("beams", s.beams as f64));
        }
        if !fin(s.angle_min)
            || !pos(s.angle_increment)
            || s.angle_increment * s.beams as f32 > core::f32::consts::TAU * 1.0001
        {
            return Err(BadParam::new(
                "angle_increment",
                if fin(s.angle_min) {
                    s.angle_increment as f64
                } else {
                    s.angle_min as f64
                },
            ));
        }
        if !pos(s.range_max)
            || s.range_min.is_nan()
            || s.range_min < 0.0
            || s.range_min >= s.range_max
        {
            return Err(BadParam::new(
                "range_max/range_min",
                if pos(s.range_max) {
                    s.range_min as f64
                } else {
                    s.range_max as f64
                },
            ));
        }
        if !(fin(s.offset.x) && fin(s.offset.y) && fin(s.offset.theta)) {
            return Err(BadParam::new(
                "sensor offset",
                first_bad(&[s.offset.x, s.offset.y, s.offset.theta], fin),
            ));
        }
        if !pos(self.resample_spacing) {
            return Err(BadParam::new(
                "resample_spacing",
                self.resample_spacing as f64,
            ));
        }
        if self.max_points < 8 || self.max_points > MAX_POINTS {
            return Err(BadParam::new("max_points", self.max_points as f64));
        }
        if !pos(self.jump_distance) {
            return Err(BadParam::new("jump_distance", self.jump_distance as f64));
        }
        if self.hist_rho_bins == 0
            || self.hist_theta_bins == 0
            || self.hist_rho_bins as u64 * self.hist_theta_bins as u64 > MAX_HIST_CELLS as u64
        {
            return Err(BadParam::new(
                "histogram bins",
                self.hist_rho_bins as f64 * self.hist_theta_bins as f64,
            ));
        }
        if !pos(self.hist_rho_max) {
            return Err(BadParam::new("hist_rho_max", self.hist_rho_max as f64));
        }
        if self.nc_min == 0 || self.nc_max < self.nc_min || self.nc_max > MAX_CANDIDATES {
            return Err(BadParam::new(
                "nc_min/nc_max",
                if self.nc_min == 0 {
                    0.0
                } else {
                    self.nc_max as f64
                },
            ));
        }
        if !(fin(self.nc_margin) && self.nc_margin >= 0.0) {
            return Err(BadParam::new("nc_margin", self.nc_margin as f64));
        }
        if !pos(self.desc_radius) {
            return Err(BadParam::new("desc_radius", self.desc_radius as f64));
        }
        if self.tentative_k == 0 || self.tentative_k > MAX_TENTATIVE_K {
            return Err(BadParam::new("tentative_k", self.tentative_k as f64));
        }
        if !pos(self.max_rho_dev) {
            return Err(BadParam::new("max_rho_dev", self.max_rho_dev as f64));
        }
        if !self.w.iter().all(|v| v.is_finite()) {
            return Err(BadParam::new("w", first_bad(&self.w, fin)));
        }
        if self.power_iters == 0 || self.power_iters > 1000 {
            return Err(BadParam::new("power_iters", self.power_iters as f64));
        }
        if !(self.binarize_frac >= 0.0 && self.binarize_frac < 1.0) {
            return Err(BadParam::new("binarize_frac", self.binarize_frac as f64));
        }
        if self.ransac_iters == 0 || self.ransac_iters > 100_000 {
            return Err(BadParam::new("ransac_iters", self.ransac_iters as f64));
        }
        if !pos(self.ransac_threshold) {
            return Err(BadParam::new(
                "ransac_threshold",
                self.ransac_threshold as f64,
            ));
        }
        if self.min_inliers < 2 {
            return Err(BadParam::new("min_inliers", self.min_inliers as f64));
        }
        if self.refine_iters > 1000 || !pos(self.refine_max_dist) {
            return Err(BadParam::new(
                "refine",
                if self.refine_iters > 1000 {
                    self.refine_iters as f64
                } else {
                    self.refine_max_dist as f64
                },
            ));
        }
        if !pos(self.sigma_d) {
            return Err(BadParam::new("sigma_d", self.sigma_d as f64));
        }
        if !(self.accept_ratio >= 0.0 && self.accept_ratio <= 1.0) {
            return Err(BadParam::new("accept_ratio", self.accept_ratio as f64));
        }
        let two_pi = 2.0 * core::f32::consts::PI;
        if !self
            .win_widths
            .iter()
            .all(|w| *w == 0.0 || (w.is_finite() && *w > 0.0 && *w < two_pi))
        {
            return Err(BadParam::new(
                "win_widths",
                first_bad(&self.win_widths, |w| {
                    w == 0.0 || (w.is_finite() && w > 0.0 && w < two_pi)
                }),
            ));
        }
        if self.win_widths[0] == 0.0 && self.win_widths[1] != 0.0
            || (self.win_count() == 2 && self.win_widths[1] <= self.win_widths[0])
        {
            return Err(BadParam::new("win_widths order", self.win_widths[1] as f64));
        }
        if self.win_count() > 0
            && (self.win_headings == 0
                || self.win_headings > 64
                || self.win_rho_bins == 0
                || self.win_theta_bins == 0
                || self.win_rho_bins as u64 * self.win_theta_bins as u64 > MAX_HIST_CELLS as u64)
        {
            return Err(BadParam::new(
                "window histogram layout",
                if self.win_headings == 0 || self.win_headings > 64 {
                    self.win_headings as f64
                } else {
                    self.win_rho_bins as f64 * self.win_theta_bins as f64
                },
            ));
        }
        if self.affinity_cap < 64 || self.affinity_cap > 1 << 20 {
            return Err(BadParam::new("affinity_cap", self.affinity_cap as f64));
        }
        if !(self.ambiguity_ratio >= 0.0 && self.ambiguity_ratio <= 1.0) {
            return Err(BadParam::new(
                "ambiguity_ratio",
                self.ambiguity_ratio as f64,
            ));
        }
        if !(self.through_max >= 0.0 && self.through_max <= 1.0) {
            return Err(BadParam::new("through_max", self.through_max as f64));
        }
        if !(self.through_excess.is_finite() && self.through_excess >= 0.0) {
            return Err(BadParam::new("through_excess", self.through_excess as f64));
        }
        if !(self.short_weight >= 0.0 && self.short_weight <= 1.0) {
            return Err(BadParam::new("short_weight", self.short_weight as f64));
        }
        if self.through_run > 64 {
            return Err(BadParam::new("through_run", self.through_run as f64));
        }
        if !(self.occlusion_fit >= 0.0 && self.occlusion_fit <= 1.0) {
            return Err(BadParam::new("occlusion_fit", self.occlusion_fit as f64));
        }
        if !(self.early_accept >= 0.0 && self.early_accept <= 1.0) {
            return Err(BadParam::new("early_accept", self.early_accept as f64));
        }
        if self.min_valid_points < 3 {
            return Err(BadParam::new(
                "min_valid_points",
                self.min_valid_points as f64,
            ));
        }
        Ok(())
    }

    /// Reads a record (no validation; call [`Params::validate`]).
    pub fn from_record(r: &ParamsRecord) -> Result<Params, BadParam> {
        Ok(Params {
            sensor: SensorModel {
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
            },
            resample_spacing: r.resample_spacing.get(),
            max_points: r.max_points.get(),
            jump_distance: r.jump_distance.get(),
            hist_rho_bins: r.hist_rho_bins.get(),
            hist_theta_bins: r.hist_theta_bins.get(),
            hist_rho_max: r.hist_rho_max.get(),
            nc_min: r.nc_min.get(),
            nc_max: r.nc_max.get(),
            nc_margin: r.nc_margin.get(),
            desc_radius: r.desc_radius.get(),
            tentative_k: r.tentative_k.get(),
            max_rho_dev: r.max_rho_dev.get(),
            w: [r.w[0].get(), r.w[1].get(), r.w[2].get()],
            power_iters: r.power_iters.get(),
            binarize_frac: r.binarize_frac.get(),
            ransac_iters: r.ransac_iters.get(),
            ransac_threshold: r.ransac_threshold.get(),
            ransac_seed: r.ransac_seed.get(),
            min_inliers: r.min_inliers.get(),
            refine_iters: r.refine_iters.get(),
            refine_max_dist: r.refine_max_dist.get(),
            sigma_d: r.sigma_d.get(),
            accept_ratio: r.accept_ratio.get(),
            min_valid_points: r.min_valid_points.get(),
            selection: match r.selection.get() {
                0 => Selection::MatchScore,
                1 => Selection::Vicinity,
                v => return Err(BadParam::new("selection", v as f64)),
            },
            early_accept: r.early_accept.get(),
            win_widths: [r.win_widths[0].get(), r.win_widths[1].get()],
            win_headings: r.win_headings.get(),
            win_rho_bins: r.win_rho_bins.get(),
            win_theta_bins: r.win_theta_bins.get(),
            early_min: r.early_min.get(),
            ambiguity_ratio: r.ambiguity_ratio.get(),
            affinity_cap: r.affinity_cap.get(),
            through_max: r.through_max.get(),
            through_excess: r.through_excess.get(),
            short_weight: r.short_weight.get(),
            through_run: r.through_run.get(),
            occlusion_fit: r.occlusion_fit.get(),
        })
    }

    /// The on-disk record.
    pub fn to_record(&self) -> ParamsRecord {
        let s = &self.sensor;
        ParamsRecord {
            beams: U32::new(s.beams),
            angle_min: F32::new(s.angle_min),
            angle_increment: F32::new(s.angle_increment),
            range_max: F32::new(s.range_max),
            range_min: F32::new(s.range_min),
            sensor_x: F32::new(s.offset.x),
            sensor_y: F32::new(s.offset.y),
            sensor_theta: F32::new(s.offset.theta),
            resample_spacing: F32::new(self.resample_spacing),
            max_points: U32::new(self.max_points),
            jump_distance: F32::new(self.jump_distance),
            hist_rho_bins: U32::new(self.hist_rho_bins),
            hist_theta_bins: U32::new(self.hist_theta_bins),
            hist_rho_max: F32::new(self.hist_rho_max),
            nc_min: U32::new(self.nc_min),
            nc_max: U32::new(self.nc_max),
            nc_margin: F32::new(self.nc_margin),
            desc_radius: F32::new(self.desc_radius),
            tentative_k: U32::new(self.tentative_k),
            max_rho_dev: F32::new(self.max_rho_dev),
            w: [
                F32::new(self.w[0]),
                F32::new(self.w[1]),
                F32::new(self.w[2]),
            ],
            power_iters: U32::new(self.power_iters),
            binarize_frac: F32::new(self.binarize_frac),
            ransac_iters: U32::new(self.ransac_iters),
            ransac_threshold: F32::new(self.ransac_threshold),
            ransac_seed: U32::new(self.ransac_seed),
            min_inliers: U32::new(self.min_inliers),
            refine_iters: U32::new(self.refine_iters),
            refine_max_dist: F32::new(self.refine_max_dist),
            sigma_d: F32::new(self.sigma_d),
            accept_ratio: F32::new(self.accept_ratio),
            min_valid_points: U32::new(self.min_valid_points),
            selection: U32::new(match self.selection {
                Selection::MatchScore => 0,
                Selection::Vicinity => 1,
            }),
            early_accept: F32::new(self.early_accept),
            win_widths: [F32::new(self.win_widths[0]), F32::new(self.win_widths[1])],
            win_headings: U32::new(self.win_headings),
            win_rho_bins: U32::new(self.win_rho_bins),
            win_theta_bins: U32::new(self.win_theta_bins),
            early_min: U32::new(self.early_min),
            ambiguity_ratio: F32::new(self.ambiguity_ratio),
            affinity_cap: U32::new(self.affinity_cap),
            through_max: F32::new(self.through_max),
            through_excess: F32::new(self.through_excess),
            short_weight: F32::new(self.short_weight),
            through_run: U32::new(self.through_run),
            occlusion_fit: F32::new(self.occlusion_fit),
        }
    }
}
