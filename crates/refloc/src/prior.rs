//! Priors: what the caller already knows about the pose (the robot is in
//! this room, faces roughly that way, is at its dock). With a prior, sites
//! outside the region are not ranked and poses outside the region or the
//! heading window are not answers; with none, nothing changes.
//!
//! A prior has at most one region: a circle ([`Prior::circle`]) or a
//! polygon ([`Prior::polygon`]), never both (a polygon prior's `radius` is
//! infinite; [`Prior::is_valid`] refuses one with both). Either can carry a
//! heading window ([`Prior::with_heading`]).

use crate::localize::Candidate;
use crate::Pose2;
use core::fmt;

/// Sites farther than this (m) beyond the region's edge are not ranked: a
/// reference site is a viewpoint near the robot, not the robot's position,
/// so sites just outside the region still see it.
pub const SITE_MARGIN: f32 = 2.0;

/// Most vertices a [`Polygon`] holds (it lives in a fixed array, so that a
/// [`Prior`] stays `Copy` and needs no allocation). The array makes every
/// `Prior` (and the `Localizer` that holds one) 264 bytes larger, with or
/// without a polygon: the firmware demo's stack peak grew by 288 bytes.
pub const MAX_POLYGON_VERTICES: usize = 32;

/// Points this close to a polygon's edge (m) count as inside it: the
/// boundary belongs to the region, whatever the rounding of the crossing
/// test.
const ON_EDGE: f32 = 1e-4;

/// A polygon region in the map frame (vertices in m), for [`Prior::polygon`].
///
/// Built only by [`Polygon::new`] / [`Polygon::from_flat`], which check it:
/// 3 to [`MAX_POLYGON_VERTICES`] finite vertices, not all on one line. The
/// vertices go around the boundary in either direction; the last connects
/// back to the first (do not repeat the first vertex).
///
/// Inside means the even-odd (crossing number) rule, with the boundary
/// included: for a simple polygon (edges that meet only at shared
/// vertices) that is the usual interior plus its edges. A self-intersecting
/// polygon is accepted, and a point is inside where a ray from it crosses
/// the edges an odd number of times: the parts the outline wraps twice (the
/// centre of a five-pointed star drawn as one stroke) are outside.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Polygon {
    /// Vertices (x, y) in m, map frame; entries past `len` are zero.
    xy: [[f32; 2]; MAX_POLYGON_VERTICES],
    /// Vertices in use (3..=MAX_POLYGON_VERTICES).
    len: u8,
}

/// Why [`Polygon::new`] refused a vertex list.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum PolygonError {
    /// Fewer than 3 vertices.
    TooFewVertices {
        /// Vertices given.
        got: usize,
    },
    /// More than [`MAX_POLYGON_VERTICES`] vertices.
    TooManyVertices {
        /// Vertices given.
        got: usize,
        /// The capacity.
        max: usize,
    },
    /// A flat `x0, y0, x1, y1, ...` list of odd length.
    OddCoordinates {
        /// Numbers given.
        got: usize,
    },
    /// A vertex with a NaN or infinite coordinate.
    NotFinite {
        /// Its index.
        vertex: usize,
    },
    /// All vertices on one line: the polygon has no area.
    Flat,
}

impl fmt::Display for PolygonError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            PolygonError::TooFewVertices { got } => {
                write!(f, "a polygon needs at least 3 vertices, got {got}")
            }
            PolygonError::TooManyVertices { got, max } => {
                write!(f, "a polygon holds at most {max} vertices, got {got}")
            }
            PolygonError::OddCoordinates { got } => write!(
                f,
                "polygon coordinates come in x, y pairs, got {got} numbers"
            ),
            PolygonError::NotFinite { vertex } => {
                write!(f, "polygon vertex {vertex} is not finite")
            }
            PolygonError::Flat => write!(f, "the polygon's vertices are all on one line"),
        }
    }
}

impl core::error::Error for PolygonError {}

impl Polygon {
    /// The polygon through `vertices` ((x, y) in m, map frame), checked.
    pub fn new(vertices: &[[f32; 2]]) -> Result<Polygon, PolygonError> {
        let got = vertices.len();
        if got < 3 {
            return Err(PolygonError::TooFewVertices { got });
        }
        if got > MAX_POLYGON_VERTICES {
            return Err(PolygonError::TooManyVertices {
                got,
                max: MAX_POLYGON_VERTICES,
            });
        }
        if let Some(vertex) = vertices
            .iter()
            .position(|v| !(v[0].is_finite() && v[1].is_finite()))
        {
            return Err(PolygonError::NotFinite { vertex });
        }
        let mut xy = [[0.0; 2]; MAX_POLYGON_VERTICES];
        xy[..got].copy_from_slice(vertices);
        let p = Polygon { xy, len: got as u8 };
        if p.is_flat() {
            return Err(PolygonError::Flat);
        }
        Ok(p)
    }

    /// The polygon through `x0, y0, x1, y1, ...` (m, map frame), checked
    /// as [`Polygon::new`] does; an odd count is
    /// [`PolygonError::OddCoordinates`].
    pub fn from_flat(xy: &[f32]) -> Result<Polygon, PolygonError> {
        if xy.len() % 2 != 0 {
            return Err(PolygonError::OddCoordinates { got: xy.len() });
        }
        let got = xy.len() / 2;
        if got > MAX_POLYGON_VERTICES {
            return Err(PolygonError::TooManyVertices {
                got,
                max: MAX_POLYGON_VERTICES,
            });
        }
        let mut v = [[0.0; 2]; MAX_POLYGON_VERTICES];
        for (d, s) in v.iter_mut().zip(xy.chunks_exact(2)) {
            *d = [s[0], s[1]];
        }
        Polygon::new(&v[..got])
    }

    /// The vertices ((x, y) in m, map frame).
    pub fn vertices(&self) -> &[[f32; 2]] {
        &self.xy[..(self.len as usize).min(MAX_POLYGON_VERTICES)]
    }

    /// The edges as (start, end) vertex pairs, the last closing the ring.
    fn edges(&self) -> impl Iterator<Item = ([f32; 2], [f32; 2])> + '_ {
        let v = self.vertices();
        v.iter()
            .zip(v.iter().cycle().skip(1))
            .map(|(a, b)| (*a, *b))
    }

    /// True when every vertex lies on the line through the first and the
    /// first one distinct from it (or all coincide).
    fn is_flat(&self) -> bool {
        let v = self.vertices();
        let o = v[0];
        let Some(a) = v.iter().find(|p| **p != o) else {
            return true;
        };
        let (ax, ay) = (a[0] - o[0], a[1] - o[1]);
        v.iter()
            .all(|p| ax * (p[1] - o[1]) - ay * (p[0] - o[0]) == 0.0)
    }

    /// True when `xy` (m, map frame) is inside by the even-odd rule
    /// (boundary points may fall either way).
    fn crosses_odd(&self, xy: [f32; 2]) -> bool {
        let [px, py] = xy;
        let mut inside = false;
        for (a, b) in self.edges() {
            // The edge straddles the horizontal through the point (so
            // a[1] != b[1]) and crosses it right of the point.
            if (a[1] > py) != (b[1] > py) && px < a[0] + (py - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
            {
                inside = !inside;
            }
        }
        inside
    }

    /// Distance (m) from `xy` (m, map frame) to the nearest edge.
    pub fn distance_to_boundary(&self, xy: [f32; 2]) -> f32 {
        let mut best = f32::INFINITY;
        for (a, b) in self.edges() {
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let (px, py) = (xy[0] - a[0], xy[1] - a[1]);
            let len2 = dx * dx + dy * dy;
            let t = if len2 > 0.0 {
                ((px * dx + py * dy) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let (ex, ey) = (px - t * dx, py - t * dy);
            best = best.min(ex * ex + ey * ey);
        }
        libm::sqrtf(best)
    }

    /// True when `xy` (m, map frame) is inside the polygon or on its
    /// boundary (within 0.1 mm of an edge).
    pub fn contains(&self, xy: [f32; 2]) -> bool {
        self.crosses_odd(xy) || self.distance_to_boundary(xy) <= ON_EDGE
    }
}

/// A region (a circle or a polygon in the map frame) and a heading window
/// for the robot pose. `radius` infinite and no `polygon`: anywhere;
/// `heading_tolerance` of pi or more: any heading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prior {
    /// Circle centre x (m, map frame).
    pub x: f32,
    /// Circle centre y (m, map frame).
    pub y: f32,
    /// Circle radius (m); `f32::INFINITY` for no circle.
    pub radius: f32,
    /// Centre of the heading window (rad, map frame).
    pub heading: f32,
    /// Half width of the heading window (rad); `PI` or more for any heading.
    pub heading_tolerance: f32,
    /// A polygon region instead of the circle (`radius` then infinite);
    /// `None` for the circle or no region.
    pub polygon: Option<Polygon>,
}

impl Prior {
    /// Anywhere, any heading.
    pub const NONE: Prior = Prior {
        x: 0.0,
        y: 0.0,
        radius: f32::INFINITY,
        heading: 0.0,
        heading_tolerance: core::f32::consts::PI,
        polygon: None,
    };

    /// A circle of `radius` m around (x, y) (m, map frame), any heading.
    pub fn circle(x: f32, y: f32, radius: f32) -> Prior {
        Prior {
            x,
            y,
            radius,
            ..Prior::NONE
        }
    }

    /// The polygon through `vertices` ((x, y) in m, map frame; see
    /// [`Polygon`]), any heading.
    pub fn polygon(vertices: &[[f32; 2]]) -> Result<Prior, PolygonError> {
        Ok(Prior {
            polygon: Some(Polygon::new(vertices)?),
            ..Prior::NONE
        })
    }

    /// This prior with a heading window of `heading` +- `tolerance` rad
    /// (map frame).
    pub fn with_heading(self, heading: f32, tolerance: f32) -> Prior {
        Prior {
            heading,
            heading_tolerance: tolerance,
            ..self
        }
    }

    /// True when the numbers make sense: finite centre and heading, radius
    /// positive (or infinite), tolerance not negative, and not both a
    /// circle and a polygon.
    pub fn is_valid(&self) -> bool {
        self.x.is_finite()
            && self.y.is_finite()
            && self.heading.is_finite()
            && self.radius > 0.0
            && !self.radius.is_nan()
            && self.heading_tolerance >= 0.0
            && (self.polygon.is_none() || self.radius == f32::INFINITY)
    }

    /// True when the prior limits the region.
    pub fn has_region(&self) -> bool {
        self.radius.is_finite() || self.polygon.is_some()
    }

    /// True when a site at `xy` (m, map frame) is ranked: within the
    /// region grown by [`SITE_MARGIN`] (for a polygon: inside it or at
    /// most that far from its edges).
    pub fn considers_site(&self, xy: [f32; 2]) -> bool {
        if let Some(poly) = &self.polygon {
            return poly.crosses_odd(xy) || poly.distance_to_boundary(xy) <= SITE_MARGIN;
        }
        if !self.has_region() {
            return true;
        }
        let r = self.radius + SITE_MARGIN;
        let (dx, dy) = (xy[0] - self.x, xy[1] - self.y);
        dx * dx + dy * dy <= r * r
    }

    /// True when the robot pose `p` (m, rad, map frame) is inside the
    /// region (boundary included) and the heading window.
    pub fn allows(&self, p: &Pose2) -> bool {
        let inside = match &self.polygon {
            Some(poly) => poly.contains([p.x, p.y]),
            None => {
                let (dx, dy) = (p.x - self.x, p.y - self.y);
                !self.has_region() || dx * dx + dy * dy <= self.radius * self.radius
            }
        };
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
    fn a_prior_is_284_bytes_as_documented() {
        assert_eq!(core::mem::size_of::<Prior>(), 284);
    }

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

    const SQUARE: [[f32; 2]; 4] = [[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]];
    /// An L: the 4 x 4 square without its upper right 2 x 2 quarter,
    /// clockwise.
    const ELL: [[f32; 2]; 6] = [
        [0.0, 0.0],
        [0.0, 4.0],
        [2.0, 4.0],
        [2.0, 2.0],
        [4.0, 2.0],
        [4.0, 0.0],
    ];

    #[test]
    fn a_square_holds_its_inside_and_its_edges() {
        let sq = Polygon::new(&SQUARE).unwrap();
        assert_eq!(sq.vertices(), &SQUARE);
        for inside in [[2.0, 2.0], [0.1, 3.9], [3.99, 0.01]] {
            assert!(sq.contains(inside), "{inside:?}");
        }
        for outside in [
            [-0.1, 2.0],
            [4.1, 2.0],
            [2.0, 5.0],
            [2.0, -1e-3],
            [1e30, 0.0],
        ] {
            assert!(!sq.contains(outside), "{outside:?}");
        }
        // Edges and corners belong to the region.
        for edge in [
            [0.0, 2.0],
            [4.0, 2.0],
            [2.0, 0.0],
            [2.0, 4.0],
            [4.0, 4.0],
            [0.0, 0.0],
        ] {
            assert!(sq.contains(edge), "{edge:?}");
            assert_eq!(sq.distance_to_boundary(edge), 0.0);
        }
        assert_eq!(sq.distance_to_boundary([2.0, 1.5]), 1.5);
        assert_eq!(sq.distance_to_boundary([7.0, 8.0]), 5.0);
        // Either direction around the boundary.
        let mut ccw = SQUARE;
        ccw.reverse();
        let back = Polygon::new(&ccw).unwrap();
        assert!(back.contains([2.0, 2.0]) && !back.contains([5.0, 2.0]));
    }

    #[test]
    fn a_concave_l_leaves_out_its_notch() {
        let ell = Polygon::from_flat(&[0.0, 0.0, 0.0, 4.0, 2.0, 4.0, 2.0, 2.0, 4.0, 2.0, 4.0, 0.0])
            .unwrap();
        assert_eq!(ell.vertices(), &ELL);
        assert!(ell.contains([1.0, 3.0]) && ell.contains([3.0, 1.0]) && ell.contains([1.0, 1.0]));
        // The notch, though inside the bounding box and the convex hull.
        assert!(!ell.contains([3.0, 3.0]));
        assert!(
            ell.contains([2.0, 3.0]) && ell.contains([3.0, 2.0]),
            "inner edges"
        );
        // A ray from these points passes through the reflex vertex (2, 2)
        // or along the edge y = 2: counted once, not twice.
        assert!(ell.contains([1.0, 2.0]) && !ell.contains([5.0, 2.0]));
        assert!(!ell.contains([-1.0, 2.0]) && !ell.contains([-1.0, 4.0]));
    }

    #[test]
    fn a_self_intersecting_polygon_uses_the_even_odd_rule() {
        // A bow tie: two triangles meeting at (1, 1).
        let bow = Polygon::new(&[[0.0, 0.0], [2.0, 2.0], [2.0, 0.0], [0.0, 2.0]]).unwrap();
        assert!(bow.contains([0.2, 1.0]) && bow.contains([1.8, 1.0]));
        assert!(!bow.contains([1.0, 0.2]) && !bow.contains([1.0, 1.8]));
        // A pentagram drawn as one stroke: its centre is wrapped twice.
        let star: [[f32; 2]; 5] = core::array::from_fn(|k| {
            let a =
                core::f32::consts::FRAC_PI_2 + (2 * k) as f32 * 2.0 * core::f32::consts::PI / 5.0;
            [libm::cosf(a), libm::sinf(a)]
        });
        let star = Polygon::new(&star).unwrap();
        assert!(!star.contains([0.0, 0.0]));
        assert!(star.contains([0.0, 0.7]), "a point of the star");
    }

    #[test]
    fn bad_vertex_lists_are_typed_errors() {
        use PolygonError::*;
        assert_eq!(Polygon::new(&[]), Err(TooFewVertices { got: 0 }));
        assert_eq!(Polygon::new(&SQUARE[..2]), Err(TooFewVertices { got: 2 }));
        let many = [[1.0, 2.0]; MAX_POLYGON_VERTICES + 1];
        assert_eq!(
            Polygon::new(&many),
            Err(TooManyVertices {
                got: MAX_POLYGON_VERTICES + 1,
                max: MAX_POLYGON_VERTICES
            })
        );
        let flat_many = [0.5; 2 * MAX_POLYGON_VERTICES + 2];
        assert!(matches!(
            Polygon::from_flat(&flat_many),
            Err(TooManyVertices { .. })
        ));
        assert_eq!(
            Polygon::from_flat(&[0.0, 0.0, 1.0, 0.0, 1.0]),
            Err(OddCoordinates { got: 5 })
        );
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let mut v = SQUARE;
            v[2][1] = bad;
            assert_eq!(Polygon::new(&v), Err(NotFinite { vertex: 2 }));
        }
        assert_eq!(
            Polygon::new(&[[0.0, 0.0], [1.0, 1.0], [3.0, 3.0]]),
            Err(Flat)
        );
        assert_eq!(Polygon::new(&[[1.0, 1.0]; 3]), Err(Flat));
        // The most that fits is fine (a circle of 32 vertices).
        let round: [[f32; 2]; MAX_POLYGON_VERTICES] = core::array::from_fn(|k| {
            let a = k as f32 * 2.0 * core::f32::consts::PI / MAX_POLYGON_VERTICES as f32;
            [libm::cosf(a), libm::sinf(a)]
        });
        assert!(Polygon::new(&round).unwrap().contains([0.5, -0.5]));
        // Every message names the problem.
        use std::string::ToString;
        assert!(Flat.to_string().contains("one line"));
        assert!(TooFewVertices { got: 2 }.to_string().contains("at least 3"));
    }

    #[test]
    fn a_polygon_prior_ranks_nearby_sites_and_allows_poses_inside() {
        let p = Prior::polygon(&ELL).unwrap().with_heading(0.0, 0.5);
        assert!(p.is_valid() && p.has_region());
        assert!(p.allows(&Pose2::new(1.0, 3.0, 0.4)));
        assert!(!p.allows(&Pose2::new(1.0, 3.0, 0.6)), "heading");
        assert!(!p.allows(&Pose2::new(3.0, 3.0, 0.0)), "the notch");
        assert!(p.allows(&Pose2::new(2.0, 4.0, 0.0)), "a corner");
        // Sites: inside, or within the margin of an edge (the notch is).
        assert!(p.considers_site([1.0, 1.0]) && p.considers_site([3.0, 3.0]));
        assert!(p.considers_site([6.0, 1.0]) && p.considers_site([-1.9, 2.0]));
        assert!(!p.considers_site([6.1, 1.0]) && !p.considers_site([5.5, 5.5]));
        // One region: a circle and a polygon together make no sense.
        assert!(!Prior { radius: 3.0, ..p }.is_valid());
        assert!(!Prior {
            heading: f32::NAN,
            ..p
        }
        .is_valid());
        assert_eq!(
            Prior::polygon(&ELL[..2]),
            Err(PolygonError::TooFewVertices { got: 2 })
        );
    }
}
