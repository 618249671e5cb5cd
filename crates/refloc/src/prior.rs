//! Priors: what the caller already knows about the pose (the robot is in
//! this room, faces roughly that way, is at its dock). With a prior, sites
//! outside the region are not ranked and poses outside the region or the
//! heading window are not answers; with none, nothing changes.

use crate::localize::Candidate;
use crate::Pose2;

/// Sites farther than this (m) beyond the region's edge are not ranked: a
/// reference site is a viewpoint near the robot, not the robot's position,
/// so sites just outside the region still see it.
pub const SITE_MARGIN: f32 = 2.0;

/// A region (a circle in the map frame) and a heading window for the robot
/// pose. `radius` infinite: anywhere; `heading_tolerance` of pi or more:
/// any heading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prior {
    /// Region centre x (m, map frame).
    pub x: f32,
    /// Region centre y (m, map frame).
    pub y: f32,
    /// Region radius (m); `f32::INFINITY` for no region.
    pub radius: f32,
    /// Centre of the heading window (rad, map frame).
    pub heading: f32,
    /// Half width of the heading window (rad); `PI` or more for any heading.
    pub heading_tolerance: f32,
}

impl Prior {
    /// Anywhere, any heading.
    pub const NONE: Prior = Prior {
        x: 0.0,
        y: 0.0,
        radius: f32::INFINITY,
        heading: 0.0,
        heading_tolerance: core::f32::consts::PI,
    };

    /// A circle of `radius` m around (x, y), any heading.
    pub fn circle(x: f32, y: f32, radius: f32) -> Prior {
        Prior {
            x,
            y,
            radius,
            ..Prior::NONE
        }
    }

    /// This prior with a heading window of `heading` +- `tolerance` rad.
    pub fn with_heading(self, heading: f32, tolerance: f32) -> Prior {
        Prior {
            heading,
            heading_tolerance: tolerance,
            ..self
        }
    }

    /// True when the numbers make sense: finite centre and heading, radius
    /// positive (or infinite), tolerance not negative.
    pub fn is_valid(&self) -> bool {
        self.x.is_finite()
            && self.y.is_finite()
            && self.heading.is_finite()
            && self.radius > 0.0
            && !self.radius.is_nan()
            && self.heading_tolerance >= 0.0
    }

    /// True when the prior limits the region.
    pub fn has_region(&self) -> bool {
        self.radius.is_finite()
    }

    /// True when a site at `xy` (m, map frame) is ranked: within the
    /// region grown by [`SITE_MARGIN`].
    pub fn considers_site(&self, xy: [f32; 2]) -> bool {
        if !self.has_region() {
            return true;
        }
        let r = self.radius + SITE_MARGIN;
        let (dx, dy) = (xy[0] - self.x, xy[1] - self.y);
        dx * dx + dy * dy <= r * r
    }

    /// True when the robot pose `p` is inside the region and the window.
    pub fn allows(&self, p: &Pose2) -> bool {
        let (dx, dy) = (p.x - self.x, p.y - self.y);
        let inside = !self.has_region() || dx * dx + dy * dy <= self.radius * self.radius;
        let facing = self.heading_tolerance >= core::f32::consts::PI
            || libm::fabsf(crate::wrap_angle(p.theta - self.heading)) <= self.heading_tolerance;
        inside && facing
    }

    /// True when candidate `c`'s pose is allowed.
    pub fn allows_candidate(&self, c: &Candidate) -> bool {
        self.allows(&Pose2::new(c.x, c.y, c.theta))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_and_heading_windows() {
        let p = Prior::circle(10.0, 5.0, 5.0).with_heading(0.0, 0.5);
        assert!(p.is_valid() && p.has_region());
        assert!(p.allows(&Pose2::new(13.0, 5.0, 0.4)));
        assert!(!p.allows(&Pose2::new(13.0, 5.0, 0.6)));
        assert!(!p.allows(&Pose2::new(16.0, 5.0, 0.0)));
        // Headings wrap.
        let back = Prior::NONE.with_heading(3.1, 0.2);
        assert!(back.allows(&Pose2::new(0.0, 0.0, -3.1)));
        // Sites: the region plus the margin.
        assert!(p.considers_site([16.5, 5.0]));
        assert!(!p.considers_site([17.5, 5.0]));
        assert!(
            Prior::NONE.considers_site([1e6, 1e6])
                && Prior::NONE.allows(&Pose2::new(1e6, 0.0, 3.0))
        );
        assert!(!Prior { radius: 0.0, ..p }.is_valid());
        assert!(!Prior { x: f32::NAN, ..p }.is_valid());
        assert!(!Prior {
            heading_tolerance: -1.0,
            ..p
        }
        .is_valid());
    }
}
