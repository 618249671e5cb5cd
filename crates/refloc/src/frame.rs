//! The map frame and its relation to grid cells (ROS map_server conventions).

/// A 2D rigid pose or transform: position in metres, heading in radians
/// (REP-103: counter-clockwise from +x).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Pose2 {
    /// x in metres.
    pub x: f32,
    /// y in metres.
    pub y: f32,
    /// Heading in radians, normalized to (-pi, pi].
    pub theta: f32,
}

/// A [`Pose2`] ready to map points: its position (m) and the sine and
/// cosine of its heading ([`Pose2::with_trig`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseTrig {
    x: f32,
    y: f32,
    s: f32,
    c: f32,
}

impl PoseTrig {
    /// Maps a point given in the pose's local frame (m) out of it.
    #[inline]
    pub fn apply(&self, p: [f32; 2]) -> [f32; 2] {
        [
            self.x + self.c * p[0] - self.s * p[1],
            self.y + self.s * p[0] + self.c * p[1],
        ]
    }
}

impl Pose2 {
    /// Builds a pose (metres, radians); the angle is normalized.
    pub fn new(x: f32, y: f32, theta: f32) -> Self {
        Pose2 {
            x,
            y,
            theta: wrap_angle(theta),
        }
    }

    /// Applies the pose to a point given in its local frame (metres).
    #[inline]
    pub fn apply(&self, p: [f32; 2]) -> [f32; 2] {
        self.with_trig().apply(p)
    }

    /// The pose with the sine and cosine of its heading computed once, to
    /// apply it to many points ([`PoseTrig::apply`] gives the same values
    /// as [`Pose2::apply`]).
    #[inline]
    pub fn with_trig(&self) -> PoseTrig {
        PoseTrig {
            x: self.x,
            y: self.y,
            s: libm::sinf(self.theta),
            c: libm::cosf(self.theta),
        }
    }

    /// Composition `self * other`: `other` expressed in `self`'s frame, mapped out.
    pub fn compose(&self, other: &Pose2) -> Pose2 {
        let p = self.apply([other.x, other.y]);
        Pose2::new(p[0], p[1], self.theta + other.theta)
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Pose2 {
        let (s, c) = (libm::sinf(self.theta), libm::cosf(self.theta));
        Pose2::new(
            -(c * self.x + s * self.y),
            s * self.x - c * self.y,
            -self.theta,
        )
    }
}

/// Wraps an angle in radians to (-pi, pi].
#[inline]
pub fn wrap_angle(a: f32) -> f32 {
    use core::f32::consts::PI;
    if !a.is_finite() {
        return a;
    }
    let mut r = libm::remainderf(a, 2.0 * PI);
    if r <= -PI {
        r += 2.0 * PI;
    }
    r
}

/// Where the grid sits in the map frame: `origin` is the map-frame pose of the
/// lower-left corner of cell (0, 0); `resolution` is metres per cell.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapFrame {
    /// Metres per cell (> 0).
    pub resolution: f32,
    /// Pose of the grid's lower-left corner in the map frame (metres, radians).
    pub origin: Pose2,
}

impl MapFrame {
    /// Map-frame point (metres) to continuous cell coordinates.
    #[inline]
    pub fn to_cells(&self, p: [f32; 2]) -> [f32; 2] {
        let (s, c) = (libm::sinf(self.origin.theta), libm::cosf(self.origin.theta));
        let (dx, dy) = (p[0] - self.origin.x, p[1] - self.origin.y);
        [
            (c * dx + s * dy) / self.resolution,
            (-s * dx + c * dy) / self.resolution,
        ]
    }

    /// Continuous cell coordinates to a map-frame point (metres).
    #[inline]
    pub fn to_map(&self, uv: [f32; 2]) -> [f32; 2] {
        self.origin
            .apply([uv[0] * self.resolution, uv[1] * self.resolution])
    }

    /// Map-frame heading (radians) to a heading in the grid's axes.
    #[inline]
    pub fn angle_to_cells(&self, theta: f32) -> f32 {
        theta - self.origin.theta
    }
}
