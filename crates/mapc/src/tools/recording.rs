//! Recordings that Foxglove (or `ros2 bag play`) opens: an MCAP file with ROS 2
//! messages (CDR, `ros2msg` schemas), as `mapc localize --mcap OUT` writes.
//!
//! Topics (all in frame `map` unless said):
//!
//! * `/map` — `nav_msgs/msg/OccupancyGrid`, once, at the first scan's time:
//!   the database's occupancy (100 occupied, 0 free; the database keeps no
//!   "unknown").
//! * `/scan` — `sensor_msgs/msg/LaserScan`, every scan, in its own frame (the
//!   bag's `frame_id`, else `laser`), stamped with the input's time.
//! * `/tf` — `tf2_msgs/msg/TFMessage`: `map` -> the scan's frame at the
//!   estimated sensor pose, for every accepted scan, so the scan shows in
//!   place.
//! * `/refloc/pose` — `geometry_msgs/msg/PoseWithCovarianceStamped`, the
//!   robot pose of every accepted scan; the 3x3 (x, y, yaw) covariance goes
//!   to rows/columns 0, 1 and 5 of the 6x6, the rest 0.
//! * `/refloc/hypotheses` — `geometry_msgs/msg/PoseArray`, the distinct
//!   hypotheses of every scan, best first.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use mcap::records::MessageHeader;
use refloc::raycast::Occupancy;
use refloc::{MapFrame, Pose2};

use crate::tools::scanio::cdr::Writer as Cdr;

const SEP: &str =
    "================================================================================\n";
const TIME: &str = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
const HEADER: &str = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
const POSE: &str = "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n";
const POINT: &str = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n";
const QUAT: &str =
    "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n";

/// A `ros2msg` schema text: the main definition, then each dependency after
/// a separator line.
fn schema(main: &str, deps: &[&str]) -> String {
    let mut s = main.to_owned();
    for d in deps {
        s.push_str(SEP);
        s.push_str(d);
    }
    s
}

/// Where a message goes and when.
pub struct Stamp<'a> {
    /// Time (ns since the epoch) for the header and the log time.
    pub ns: i64,
    /// The scan's frame.
    pub frame: &'a str,
}

/// An MCAP recording being written.
pub struct Recording {
    w: mcap::Writer<BufWriter<File>>,
    channels: BTreeMap<&'static str, u16>,
    seq: u32,
}

impl Recording {
    /// Creates `path` and registers the five topics.
    pub fn create(path: &Path) -> anyhow::Result<Recording> {
        let file = File::create(path)?;
        let mut w = mcap::WriteOptions::new()
            .profile("ros2")
            .library("refloc mapc")
            .create(BufWriter::new(file))?;
        let vec3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n";
        let defs: [(&str, &str, String); 5] = [
            (
                "/map",
                "nav_msgs/msg/OccupancyGrid",
                schema(
                    "std_msgs/Header header\nMapMetaData info\nint8[] data\n",
                    &[
                        HEADER,
                        TIME,
                        "MSG: nav_msgs/MapMetaData\nbuiltin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\nuint32 height\ngeometry_msgs/Pose origin\n",
                        POSE,
                        POINT,
                        QUAT,
                    ],
                ),
            ),
            (
                "/scan",
                "sensor_msgs/msg/LaserScan",
                schema(
                    "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\nfloat32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\nfloat32[] ranges\nfloat32[] intensities\n",
                    &[HEADER, TIME],
                ),
            ),
            (
                "/tf",
                "tf2_msgs/msg/TFMessage",
                schema(
                    "geometry_msgs/TransformStamped[] transforms\n",
                    &[
                        "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\nTransform transform\n",
                        HEADER,
                        TIME,
                        "MSG: geometry_msgs/Transform\nVector3 translation\nQuaternion rotation\n",
                        vec3,
                        QUAT,
                    ],
                ),
            ),
            (
                "/refloc/pose",
                "geometry_msgs/msg/PoseWithCovarianceStamped",
                schema(
                    "std_msgs/Header header\nPoseWithCovariance pose\n",
                    &[
                        HEADER,
                        TIME,
                        "MSG: geometry_msgs/PoseWithCovariance\nPose pose\nfloat64[36] covariance\n",
                        POSE,
                        POINT,
                        QUAT,
                    ],
                ),
            ),
            (
                "/refloc/hypotheses",
                "geometry_msgs/msg/PoseArray",
                schema(
                    "std_msgs/Header header\ngeometry_msgs/Pose[] poses\n",
                    &[HEADER, TIME, POSE, POINT, QUAT],
                ),
            ),
        ];
        let mut channels = BTreeMap::new();
        for (topic, name, text) in defs {
            let s = w.add_schema(name, "ros2msg", text.as_bytes())?;
            let c = w.add_channel(s, topic, "cdr", &BTreeMap::new())?;
            channels.insert(topic, c);
        }
        Ok(Recording {
            w,
            channels,
            seq: 0,
        })
    }

    fn put(&mut self, topic: &'static str, ns: i64, msg: Cdr) -> anyhow::Result<()> {
        let t = ns.max(0) as u64;
        self.seq += 1;
        self.w.write_to_known_channel(
            &MessageHeader {
                channel_id: self.channels[topic],
                sequence: self.seq,
                log_time: t,
                publish_time: t,
            },
            &Cow::<[u8]>::Owned(msg.into_bytes()),
        )?;
        Ok(())
    }

    /// The map, as an OccupancyGrid.
    pub fn map<G: Occupancy>(&mut self, ns: i64, frame: &MapFrame, grid: &G) -> anyhow::Result<()> {
        let (w, h) = (grid.width(), grid.height());
        let mut m = Cdr::new();
        // header, then info: map_load_time, resolution, width, height, origin.
        m.header(ns, "map");
        m.i32(ns.div_euclid(1_000_000_000) as i32)
            .u32(ns.rem_euclid(1_000_000_000) as u32)
            .f32(frame.resolution)
            .u32(w)
            .u32(h)
            .pose2(
                frame.origin.x as f64,
                frame.origin.y as f64,
                frame.origin.theta as f64,
            )
            .u32(w * h);
        for cy in 0..h {
            for cx in 0..w {
                m.u8(if grid.blocked(cx, cy) { 100 } else { 0 });
            }
        }
        self.put("/map", ns, m)
    }

    /// One scan in its frame.
    #[allow(clippy::too_many_arguments)]
    pub fn scan(
        &mut self,
        at: &Stamp,
        angle_min: f32,
        angle_increment: f32,
        range_min: f32,
        range_max: f32,
        ranges: &[f32],
    ) -> anyhow::Result<()> {
        let mut m = Cdr::new();
        m.header(at.ns, at.frame)
            .f32(angle_min)
            .f32(angle_min + angle_increment * ranges.len().saturating_sub(1) as f32)
            .f32(angle_increment)
            .f32(0.0)
            .f32(0.0)
            .f32(range_min)
            .f32(range_max)
            .f32_seq(ranges)
            .f32_seq(&[]);
        self.put("/scan", at.ns, m)
    }

    /// The transform map -> the scan's frame: the estimated sensor pose.
    pub fn tf(&mut self, at: &Stamp, sensor: &Pose2) -> anyhow::Result<()> {
        let mut m = Cdr::new();
        m.u32(1).header(at.ns, "map").string(at.frame);
        // Transform: translation (Vector3) then rotation (Quaternion), the
        // same layout as a Pose.
        m.pose2(sensor.x as f64, sensor.y as f64, sensor.theta as f64);
        self.put("/tf", at.ns, m)
    }

    /// An accepted robot pose and its (x, y, yaw) covariance.
    pub fn pose(&mut self, ns: i64, pose: &Pose2, cov: Option<[f32; 9]>) -> anyhow::Result<()> {
        let mut m = Cdr::new();
        m.header(ns, "map")
            .pose2(pose.x as f64, pose.y as f64, pose.theta as f64);
        for v in covariance_6x6(cov) {
            m.f64(v);
        }
        self.put("/refloc/pose", ns, m)
    }

    /// The distinct hypotheses, best first.
    pub fn hypotheses(&mut self, ns: i64, poses: &[Pose2]) -> anyhow::Result<()> {
        let mut m = Cdr::new();
        m.header(ns, "map").u32(poses.len() as u32);
        for p in poses {
            m.pose2(p.x as f64, p.y as f64, p.theta as f64);
        }
        self.put("/refloc/hypotheses", ns, m)
    }

    /// Writes the summary and flushes the file.
    pub fn finish(mut self) -> anyhow::Result<()> {
        self.w.finish()?;
        let mut inner = self.w.into_inner();
        inner.flush()?;
        Ok(())
    }
}

/// The 3x3 (x, y, yaw) covariance, row-major, in the 6x6 (x, y, z, roll,
/// pitch, yaw) of a `PoseWithCovariance`; all 0 without one.
pub fn covariance_6x6(cov: Option<[f32; 9]>) -> [f64; 36] {
    let mut out = [0.0; 36];
    if let Some(c) = cov {
        const AT: [usize; 3] = [0, 1, 5];
        for i in 0..3 {
            for j in 0..3 {
                out[AT[i] * 6 + AT[j]] = c[i * 3 + j] as f64;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn covariance_goes_to_x_y_yaw() {
        let c = covariance_6x6(Some([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]));
        assert_eq!((c[0], c[1], c[5]), (1.0, 2.0, 3.0));
        assert_eq!((c[6], c[7], c[11]), (4.0, 5.0, 6.0));
        assert_eq!((c[30], c[31], c[35]), (7.0, 8.0, 9.0));
        assert_eq!(c.iter().filter(|v| **v != 0.0).count(), 9);
        assert_eq!(covariance_6x6(None), [0.0; 36]);
    }
}
