//! The answer's confidence: a probability that a pose is right, from what
//! separates a right pose from a wrong one on real scans, and the decision
//! that accepts it.
//!
//! Five features of a candidate pose, each a share of the vicinity score's
//! maximum `HIT_SCORE N_P` or normalized per point (so they do not depend
//! on the beam count):
//!
//! - **evidence ratio**: its evidence (the vicinity score less the short-beam
//!   penalty, [`crate::verify::Vicinity::evidence`]) over the maximum;
//! - **margin**: how much more evidence it has than the best *distinct*
//!   alternative the fine stage found (a pose over
//!   [`crate::select::DISTINCT_DISTANCE`] or
//!   [`crate::select::DISTINCT_HEADING`] away that passes the free-space
//!   check), over the same maximum; negative when an alternative explains
//!   the scan better;
//! - **support**: `ln` of the number of examined candidates whose match
//!   landed on the same pose (not distinct from it): a right pose is found
//!   from several reference sites, a wrong one usually from one;
//! - **through share**: the share of its beams that pass through a wall of
//!   the map ([`crate::verify::Vicinity::through`]): free-space
//!   consistency, graded rather than the pass/fail check;
//! - **spread**: how loosely the scan pins the position, `ln` of
//!   [`crate::refine::position_spread`] (the fit's position standard
//!   deviation along its worst direction, per point) in units of
//!   [`spread_unit`] (0.05 m on a map of 0.05 m cells, and only a quarter
//!   power of the cell size on others, so that the feature means about
//!   the same on maps of any resolution): small
//!   where walls all round pin the pose and the points lie on them, large
//!   along a featureless corridor, which is where a pose slid along it or
//!   turned end for end elsewhere fits as well as the right one.
//!
//! The probability is a logistic model of these,
//! `p = 1 / (1 + exp(-(b + w . f)))`, whose coefficients a database stores
//! in its decision section ([`Decision`]); `accepted` is `p >= threshold`.
//! [`Decision::DEFAULT`] was fitted on real laser logs with their locally
//! corrected truth (see `docs/confidence.md`: which logs, and the figures
//! on the logs it was not fitted on).

use crate::localize::Candidate;
use crate::select::distinct;
use crate::verify;

/// Number of features of the model.
pub const FEATURES: usize = 5;

/// Bound of the spread feature (`ln` of the spread in units of
/// [`spread_unit`]): a larger spread, a pose without one, or a degenerate
/// fit, count as this.
pub const SPREAD_MAX: f32 = 3.0;

/// The spread feature's unit (m) on a map of 0.05 m cells, the cell size
/// of every map the default model was fitted on; on a map of cell `res`
/// the unit is `SPREAD_UNIT (res / SPREAD_UNIT)^SPREAD_CELL_EXPONENT`
/// ([`spread_unit`]).
pub const SPREAD_UNIT: f32 = 0.05;

/// How much of the spread's unit follows the map's cell size: 0 would
/// measure the spread in metres, 1 in cells (docs/results.md, "Maps of
/// other resolutions"). The position spread is a length (the fit's
/// residuals times the geometry's leverage) that grows with the cell on a
/// map made at that cell (right answers of real scans on maps made from
/// the logs themselves: about 0.030, 0.047 and 0.077 m at 0.025, 0.05 and
/// 0.1 m cells) but not on a map only resampled finer (0.041 and 0.042 m
/// at 0.025 and 0.05). Measured in cells (1), as before, a 0.025 m map
/// made every fit look twice as loose and a 0.1 m map twice as tight (real
/// Intel scans: 47.5% accepted and right on the shared map split to 0.025
/// m, 9.7% false accepts on it merged to 0.1 m, against 80.7 / 3.1 at
/// 0.05). The exponent was chosen among 0, 0.25, 0.5, 0.75 and 1 on the
/// Intel and ACES logs on their maps resampled to 0.025 and 0.1 m and on
/// maps made from the logs at those cells (accepted and correct less ten
/// times the false accepts, summed), and reported on the CSAIL log's
/// (held out).
pub const SPREAD_CELL_EXPONENT: f32 = 0.25;

/// The spread feature's unit (m) on a map of cell `resolution` (m); see
/// [`SPREAD_CELL_EXPONENT`]. [`SPREAD_UNIT`] for a resolution that is not
/// a positive number.
pub fn spread_unit(resolution: f32) -> f32 {
    if resolution > 0.0 && resolution.is_finite() {
        SPREAD_UNIT * libm::powf(resolution / SPREAD_UNIT, SPREAD_CELL_EXPONENT)
    } else {
        SPREAD_UNIT
    }
}

/// The spread feature of a position spread (m,
/// [`crate::refine::position_spread`]) on a map of cell `resolution` (m):
/// `ln(spread / spread_unit(resolution))` within +-[`SPREAD_MAX`];
/// [`SPREAD_MAX`] for `None` or a spread that is not a positive number.
/// On a 0.05 m map it is `ln(spread / 0.05 m)`.
pub fn spread_feature(spread: Option<f32>, resolution: f32) -> f32 {
    match spread {
        Some(s) if s > 0.0 => {
            // On a 0.05 m map the unit is exactly SPREAD_UNIT (1^x = 1).
            let f = libm::logf(s / spread_unit(resolution));
            if f.is_finite() {
                f.clamp(-SPREAD_MAX, SPREAD_MAX)
            } else {
                SPREAD_MAX
            }
        }
        _ => SPREAD_MAX,
    }
}

/// A candidate's features (see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Features {
    /// Evidence over `HIT_SCORE N_P` (dimensionless, at most about 1).
    pub evidence_ratio: f32,
    /// Evidence less the best distinct alternative's, over `HIT_SCORE N_P`.
    pub margin: f32,
    /// Examined candidates that found this pose (at least 1).
    pub support: u32,
    /// Beams through a wall over N_P (0..=1).
    pub through_share: f32,
    /// [`spread_feature`] of the pose ([`Candidate::spread`]).
    pub spread: f32,
}

impl Features {
    /// The model's inputs, in [`Decision::weights`] order.
    pub fn inputs(&self) -> [f32; FEATURES] {
        [
            self.evidence_ratio,
            self.margin,
            libm::logf(self.support.max(1) as f32),
            self.through_share,
            self.spread,
        ]
    }
}

/// The features of candidate `c` among the examined candidates `cands`
/// (candidates without a pose are ignored; `c` itself may be among them).
pub fn features(cands: &[Candidate], c: &Candidate) -> Features {
    if c.has_pose == 0 {
        return Features {
            spread: SPREAD_MAX,
            ..Features::default()
        };
    }
    // 1 / (HIT_SCORE N_P): scores times this are shares of their maximum.
    let per_max = verify::ratio(1.0, c.pairs);
    let mut alt = 0.0f32;
    let mut support = 0u32;
    for o in cands.iter().filter(|o| o.has_pose != 0) {
        if distinct(o, c) {
            if o.free_space_ok != 0 && o.evidence > alt {
                alt = o.evidence;
            }
        } else {
            support = support.saturating_add(1);
        }
    }
    Features {
        evidence_ratio: c.evidence * per_max,
        margin: (c.evidence - alt) * per_max,
        support: support.max(1),
        through_share: if c.pairs == 0 {
            0.0
        } else {
            c.through_beams as f32 / c.pairs as f32
        },
        spread: c.spread,
    }
}

/// A logistic confidence model and the acceptance threshold.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decision {
    /// The model's intercept.
    pub bias: f32,
    /// Weights of the evidence ratio, the margin, `ln` support, the
    /// through share and the spread.
    pub weights: [f32; FEATURES],
    /// A pose is accepted when its confidence is at least this (0..=1).
    pub threshold: f32,
}

impl Decision {
    /// The model `mapc build` stores by default: fitted (maximum likelihood,
    /// L2 1e-3, `scripts/fit-confidence.py` on the sets of
    /// `scripts/confidence-sets.sh`) on 3,549 answers labelled right when
    /// within 0.3 m and 5 degrees of the truth: the real Intel and ACES logs
    /// (1,350 scans, against their locally corrected truth) and simulated
    /// scans of the Intel map (360 and 180 degrees, static and dynamic), of
    /// tb3-world (a symmetric map) and of the ACES map localized on the
    /// Intel database (all wrong). CSAIL, nav2-warehouse, willow-full,
    /// synthetic offices and CSAIL scans on ACES were kept out of the fit
    /// to report on (`docs/confidence.md`). The spread carries most of
    /// what the evidence ratio said about the fit (it grows with the
    /// points' distance to the surfaces), so the evidence ratio's own weight
    /// is near zero. The threshold 0.8 is where, on the fitted data, false
    /// accepts fall to about 2.5% (Intel) and 1.8% (ACES) of the real scans
    /// while the simulated sets lose at most 2% of their correct answers.
    pub const DEFAULT: Decision = Decision {
        bias: -0.129,
        weights: [0.039, 3.514, 1.496, -22.390, -4.782],
        threshold: 0.8,
    };

    /// The probability (0..=1) that a pose with features `f` is right.
    pub fn probability(&self, f: &Features) -> f32 {
        let x = f.inputs();
        let mut z = self.bias;
        for (w, v) in self.weights.iter().zip(x) {
            z += w * v;
        }
        if !z.is_finite() {
            return 0.0;
        }
        1.0 / (1.0 + libm::expf(-z.clamp(-40.0, 40.0)))
    }

    /// True when the model's numbers are finite and the threshold is in
    /// 0..=1.
    pub fn is_valid(&self) -> bool {
        self.bias.is_finite()
            && self.weights.iter().all(|w| w.is_finite())
            && (0.0..=1.0).contains(&self.threshold)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cand(x: f32, y: f32, theta: f32, evidence: f32) -> Candidate {
        Candidate {
            x,
            y,
            theta,
            evidence,
            vicinity: evidence,
            pairs: 100,
            has_pose: 1,
            free_space_ok: 1,
            spread: RIGHT_SPREAD,
            ..Candidate::default()
        }
    }

    /// A typical spread of right answers on the real logs
    /// (`docs/confidence.md`).
    const RIGHT_SPREAD: f32 = -0.3;

    #[test]
    fn a_pose_found_from_many_sites_with_no_rival_is_confident() {
        let best = cand(0.0, 0.0, 0.0, 400.0);
        let cands = [
            best,
            cand(0.01, 0.0, 0.0, 398.0),
            cand(0.0, 0.02, 0.01, 399.0),
        ];
        let f = features(&cands, &best);
        assert_eq!(f.support, 3);
        assert!((f.evidence_ratio - 400.0 / 450.0).abs() < 1e-6);
        assert!((f.margin - f.evidence_ratio).abs() < 1e-6);
        assert!(Decision::DEFAULT.probability(&f) > 0.99);
    }

    #[test]
    fn a_right_pose_with_moved_furniture_is_still_accepted() {
        // Half the beams blocked by unmapped things (low evidence), but no
        // distinct place explains the scan, and three sites agree.
        let best = cand(0.0, 0.0, 0.0, 260.0);
        let cands = [
            best,
            cand(0.02, 0.0, 0.0, 255.0),
            cand(0.0, 0.03, 0.0, 250.0),
            cand(7.0, 3.0, 1.0, 40.0),
        ];
        let p = Decision::DEFAULT.probability(&features(&cands, &best));
        assert!(p >= Decision::DEFAULT.threshold, "{p}");
    }

    #[test]
    fn a_wrong_pose_that_fits_a_corridor_is_rejected() {
        // A corridor: the pose fits fairly, but a pose 3 m along the
        // corridor fits almost as well and no other site found it.
        // Its points pin the position loosely along the corridor: about the
        // median spread of the wrong answers on the real logs.
        let mut best = cand(0.0, 0.0, 0.0, 300.0);
        best.spread = 0.4;
        let along = cand(3.0, 0.0, 0.0, 280.0);
        let p = Decision::DEFAULT.probability(&features(&[best, along], &best));
        assert!(p < Decision::DEFAULT.threshold, "{p}");
    }

    #[test]
    fn a_pose_the_scan_does_not_pin_is_not_confident() {
        // The same support and fit as a confident answer, but its points
        // leave the position loose (a featureless corridor).
        let mut best = cand(0.0, 0.0, 0.0, 400.0);
        let cands = [best, cand(0.01, 0.0, 0.0, 398.0)];
        let pinned = Decision::DEFAULT.probability(&features(&cands, &best));
        best.spread = 1.5;
        let loose = Decision::DEFAULT.probability(&features(&cands, &best));
        assert!(pinned >= Decision::DEFAULT.threshold, "{pinned}");
        assert!(loose < Decision::DEFAULT.threshold, "{loose}");
    }

    #[test]
    fn spread_feature_is_log_units_and_bounded() {
        let res = 0.05;
        assert_eq!(spread_feature(Some(SPREAD_UNIT), res), 0.0);
        assert!((spread_feature(Some(2.0 * SPREAD_UNIT), res) - 2f32.ln()).abs() < 1e-6);
        assert_eq!(spread_feature(Some(1e6), res), SPREAD_MAX);
        assert_eq!(spread_feature(Some(1e-9), res), -SPREAD_MAX);
        assert_eq!(spread_feature(None, res), SPREAD_MAX);
        assert_eq!(spread_feature(Some(f32::NAN), res), SPREAD_MAX);
        assert_eq!(spread_feature(Some(-1.0), res), SPREAD_MAX);
        // A bad resolution counts as 0.05 m.
        assert_eq!(
            spread_feature(Some(0.1), f32::NAN),
            spread_feature(Some(0.1), res)
        );
        assert_eq!(
            spread_feature(Some(0.1), 0.0),
            spread_feature(Some(0.1), res)
        );
    }

    #[test]
    fn the_spread_unit_follows_a_quarter_power_of_the_cell() {
        assert_eq!(spread_unit(0.05), SPREAD_UNIT);
        // Half the cell: the unit shrinks by 2^-1/4, not by half.
        assert!((spread_unit(0.025) - 0.05 * 0.5f32.powf(0.25)).abs() < 1e-6);
        assert!((spread_unit(0.1) - 0.05 * 2f32.powf(0.25)).abs() < 1e-6);
        // The feature is the log of the spread in that unit.
        for res in [0.025f32, 0.1] {
            let s = 0.07;
            let f = spread_feature(Some(s), res);
            assert!((f - (s / spread_unit(res)).ln()).abs() < 1e-5, "{res}: {f}");
        }
        assert_eq!(spread_unit(-1.0), SPREAD_UNIT);
    }

    #[test]
    fn a_rival_that_fails_the_free_space_check_is_no_rival() {
        let best = cand(0.0, 0.0, 0.0, 300.0);
        let mut through = cand(5.0, 0.0, 0.0, 320.0);
        through.free_space_ok = 0;
        let f = features(&[best, through], &best);
        assert!((f.margin - f.evidence_ratio).abs() < 1e-6);
    }

    #[test]
    fn no_pose_or_bad_numbers_give_zero() {
        let none = Candidate::default();
        assert_eq!(features(&[none], &none).evidence_ratio, 0.0);
        assert_eq!(features(&[none], &none).spread, SPREAD_MAX);
        let d = Decision {
            bias: f32::NAN,
            ..Decision::DEFAULT
        };
        assert!(!d.is_valid());
        assert_eq!(d.probability(&Features::default()), 0.0);
        assert!(Decision::DEFAULT.is_valid());
    }
}
