//! `mapc localize`: one JSON object (or table row) per input scan.

use std::collections::HashMap;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use mapc::tools::scanio::{self, InputFormat, ReadOptions, ScanData};
use refloc::scratch_size;
use serde_json::json;

use crate::util::{fail_err, input_err, open_db, Check, CliError, CliResult, DbBytes, Ui};

/// Where the results go: standard output, every write checked.
///
/// A write error (a full disk, `> /dev/full`) ends the run with exit 1 and
/// says so; a closed pipe (`| head -1`) stops the run quietly, since nobody
/// reads the rest. When the scans come from a stream (stdin, a FIFO), each
/// result is flushed as soon as it is computed, so a live consumer sees it
/// before the next scan arrives; from a regular file the output is buffered.
struct Sink<W: Write> {
    out: std::io::BufWriter<W>,
    flush_each: bool,
    /// The reader has gone (a write met a closed pipe): stop localizing.
    closed: bool,
}

impl<W: Write> Sink<W> {
    fn new(w: W, flush_each: bool) -> Sink<W> {
        Sink {
            out: std::io::BufWriter::new(w),
            flush_each,
            closed: false,
        }
    }

    /// Writes one line (a newline is added); nothing once closed.
    fn line(&mut self, s: &str) -> Result<(), CliError> {
        if self.closed {
            return Ok(());
        }
        let r = writeln!(self.out, "{s}").and_then(|()| {
            if self.flush_each {
                self.out.flush()
            } else {
                Ok(())
            }
        });
        self.outcome(r)
    }

    /// Flushes what is buffered; nothing once closed.
    fn finish(&mut self) -> Result<(), CliError> {
        if self.closed {
            return Ok(());
        }
        let r = self.out.flush();
        self.outcome(r)
    }

    fn outcome(&mut self, r: std::io::Result<()>) -> Result<(), CliError> {
        match r {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {
                self.closed = true;
                Ok(())
            }
            Err(e) => Err(fail_err(anyhow::anyhow!(
                "cannot write the results to standard output: {e}"
            ))),
        }
    }
}

/// True when `input` names a stream (stdin, a FIFO, a character device)
/// rather than a regular file: results are then flushed one by one.
fn is_stream(input: &str) -> bool {
    input == "-" || std::fs::metadata(input).map_or(true, |m| !m.is_file())
}

/// A bag scan's header stamp (ns since the epoch) and frame in its JSON result.
fn add_stamp(o: &mut serde_json::Value, scan: &scanio::InputScan) {
    if let Some(st) = &scan.stamp {
        o["stamp_ns"] = json!(st.ns);
        o["log_time_ns"] = json!(st.log_time_ns);
        o["frame_id"] = json!(st.frame_id);
    }
}

/// Every input and output format, for `mapc localize --help`.
pub const FORMATS: &str = "\
Input formats (--input-format auto decides: an MCAP file by its magic, else by the first line):
  jsonl   JSON Lines, one sensor_msgs/LaserScan-like object per line: angle_min,
          angle_increment, range_min, range_max, ranges (null = no return), optional
          angle_max, id, truth [x, y, theta]; or points [[x, y], ...] instead of ranges.
          Plain or gzip (.gz); '-' reads stdin (results then flushed one by one).
  carmen  CARMEN logs: FLASER, RLASER, ROBOTLASERk lines (--fov for FLASER/RLASER).
  mcap    ROS 2 bags in rosbag2's MCAP storage: sensor_msgs/msg/LaserScan (CDR) of one
          topic (--topic when the bag has several); chunks uncompressed, zstd or lz4.
Outputs:
  stdout  --format json: one object per scan (pose, accepted, confidence, covariance,
          hypotheses, candidates, timing; stamp_ns, log_time_ns, frame_id for bag scans;
          errors as {\"id\", \"line\", \"error\"}). --format text: a table.
  --mcap  a Foxglove-readable MCAP recording of ROS 2 messages: /map (nav_msgs/OccupancyGrid),
          /scan (sensor_msgs/LaserScan), /tf (tf2_msgs/TFMessage map -> laser frame),
          /refloc/pose (geometry_msgs/PoseWithCovarianceStamped), /refloc/hypotheses
          (geometry_msgs/PoseArray).
  stderr  a summary (scans, unreadable, accepted, median time; against --truth if given).
Exit: 0 all scans read, 1 some scan unreadable (or a bag cut off) or a write failed, 2 bad input.
See docs/robot.md.";

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The database; several (floors, buildings) to ask which map each scan is on.
    #[arg(required = true, num_args = 1.., value_name = "DB")]
    pub db: Vec<PathBuf>,
    /// Scans: JSON Lines (sensor_msgs/LaserScan fields), a CARMEN log (.gz ok; "-" reads stdin), or a ROS 2 bag (rosbag2 MCAP, .mcap).
    pub input: String,
    /// Output.
    #[arg(long, value_enum, default_value_t = OutputFormat::Json)]
    pub format: OutputFormat,
    /// Input format.
    #[arg(long, value_enum, ignore_case = true, default_value_t = InputKind::Auto)]
    pub input_format: InputKind,
    /// The sensor_msgs/msg/LaserScan topic of a bag; needed only when the bag has several.
    #[arg(long, value_name = "TOPIC")]
    pub topic: Option<String>,
    /// Field of view of CARMEN FLASER/RLASER lines (degrees) [default: 180].
    #[arg(long, value_name = "DEG")]
    pub fov: Option<f32>,
    /// Maximum range when the input gives none (m).
    #[arg(long, default_value_t = 30.0, value_name = "M")]
    pub range_max: f32,
    /// Ground truth in the map frame, `index ... x y theta` per line (the
    /// shared `*-poses-in-map.txt` format): adds errors and a summary, also
    /// against each truth pose corrected locally against the map
    /// (`truth_refined` in the JSON; see docs/results.md).
    #[arg(long, value_name = "FILE")]
    pub truth: Option<PathBuf>,
    /// Also write a Foxglove-readable recording (MCAP, ROS 2 messages): /map, /scan, /tf (map -> laser), /refloc/pose, /refloc/hypotheses. Scans without a stamp (JSON Lines, CARMEN) are placed 100 ms apart from time 0.
    #[arg(long, value_name = "OUT.mcap")]
    pub mcap: Option<PathBuf>,
    /// Leave the candidate list out of the JSON output.
    #[arg(long)]
    pub no_candidates: bool,
    /// Localize scans of a short-reach sensor (under half the database's
    /// reference reach) on the database's own reference scans. Without it
    /// they are localized on reference scans made again for their reach
    /// (rounded down to 0.1 m) from the database (`mapc::compiler::reach`,
    /// well under a second for the shared maps, once per run and reach), as
    /// a database built with `--range-max` for that sensor stores them;
    /// either way every candidate is examined.
    #[arg(long)]
    pub database_reach: bool,
    /// Prior region: the robot is within R m of (X, Y) (map frame); sites
    /// outside it (plus 2 m) are not ranked, poses outside it are no answer.
    #[arg(long, value_name = "X,Y,R", allow_hyphen_values = true)]
    pub prior: Option<Numbers>,
    /// Prior heading window: the robot faces THETA +- TOL degrees (map frame).
    #[arg(long, value_name = "THETA,TOL", allow_hyphen_values = true)]
    pub prior_heading: Option<Numbers>,
    /// Prior region as a polygon: the robot is inside the polygon through
    /// (X1, Y1), (X2, Y2), ... (m, map frame; 3 to 32 vertices, the last
    /// joins the first); sites more than 2 m outside it are not ranked,
    /// poses outside it are no answer. Instead of --prior.
    #[arg(
        long,
        value_name = "X1,Y1,X2,Y2,...",
        allow_hyphen_values = true,
        conflicts_with = "prior",
        value_parser = parse_polygon
    )]
    pub prior_polygon: Option<refloc::Polygon>,
}

/// `--prior-polygon`: comma-separated x, y pairs, checked by the runtime's
/// rules (`refloc::Polygon::from_flat`).
fn parse_polygon(s: &str) -> Result<refloc::Polygon, String> {
    let Numbers(xy) = s.parse()?;
    refloc::Polygon::from_flat(&xy).map_err(|e| e.to_string())
}

/// A comma-separated list of numbers in one argument (`--prior 1,-2,3`):
/// one value for clap, so `--help` shows its name once.
#[derive(Clone, Debug, PartialEq)]
pub struct Numbers(pub Vec<f32>);

impl std::str::FromStr for Numbers {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        s.split(',')
            .map(|t| {
                t.trim()
                    .parse::<f32>()
                    .map_err(|e| format!("{t:?} is not a number: {e}"))
            })
            .collect::<Result<Vec<f32>, String>>()
            .map(Numbers)
    }
}

/// The scans of a stream of results.
type Scans = Box<dyn Iterator<Item = Result<scanio::InputScan, scanio::ScanError>>>;

/// `mapc localize --input-format`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum InputKind {
    /// An MCAP file by its magic, else by the first line.
    Auto,
    /// JSON Lines, sensor_msgs/LaserScan fields.
    #[value(alias = "json", alias = "jsonlines", alias = "json-lines")]
    Jsonl,
    /// A CARMEN log.
    #[value(alias = "log")]
    Carmen,
    /// A ROS 2 bag (rosbag2 MCAP).
    #[value(alias = "bag", alias = "rosbag2")]
    Mcap,
}

/// Opens the input the options name: a ROS 2 bag (by `--input-format` or
/// its magic), else JSON Lines or a CARMEN log (a file or stdin).
fn scan_source(a: &Args, ui: &Ui) -> Result<Scans, CliError> {
    if a.input != "-" && scanio::bag::is_sqlite(std::path::Path::new(&a.input)) {
        return Err(input_err(anyhow::anyhow!(
            "{} is an SQLite file (a rosbag2 sqlite3 .db3 bag?); mapc reads rosbag2's MCAP storage only: convert it with `ros2 bag convert` or `rosbags-convert --src BAG_DIR --dst OUT_DIR --dst-storage mcap`",
            a.input
        )));
    }
    let (want_bag, fmt) = match a.input_format {
        InputKind::Mcap => (true, InputFormat::Auto),
        InputKind::Auto => (
            a.input != "-" && scanio::bag::is_mcap(std::path::Path::new(&a.input)),
            InputFormat::Auto,
        ),
        InputKind::Jsonl => (false, InputFormat::JsonLines),
        InputKind::Carmen => (false, InputFormat::Carmen),
    };
    if a.topic.is_some() && !want_bag {
        return Err(input_err(anyhow::anyhow!(
            "--topic applies to ROS 2 bags (MCAP) only; {} is not one",
            a.input
        )));
    }
    let opts = ReadOptions {
        fov: a.fov.map(|d| d.to_radians()),
        range_max: a.range_max,
        ..ReadOptions::default()
    };
    Ok(if want_bag {
        let bag = scanio::bag::open_bag(std::path::Path::new(&a.input), a.topic.as_deref())
            .map_err(input_err)?;
        ui.note(&format!(
            "{}: topic {}{}",
            a.input,
            bag.topic,
            bag.damage
                .as_ref()
                .map(|d| format!(" (damaged: {d})"))
                .unwrap_or_default()
        ));
        Box::new(
            bag.scans(&opts)
                .map_err(|e| input_err(anyhow::anyhow!("{}: {e}", a.input)))?,
        )
    } else {
        let reader = scanio::open_input(&a.input)
            .map_err(|e| input_err(anyhow::anyhow!("{}: {e}", a.input)))?;
        Box::new(scanio::read_scans(reader, fmt, &opts))
    })
}

/// The output line for an input scan that could not be read.
fn unreadable_line(e: &scanio::ScanError, text: bool) -> String {
    if text {
        format!(
            "{:<12} error: {}",
            e.id.clone().unwrap_or_else(|| format!("line {}", e.line)),
            e.kind
        )
    } else {
        json!({"id": e.id, "line": e.line, "error": e.message()}).to_string()
    }
}

/// `mapc localize --format`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum OutputFormat {
    /// One JSON object per line.
    Json,
    /// A table.
    Text,
}

/// `--format`: text (true) or JSON (false).
fn output_is_text(a: &Args) -> Result<bool, CliError> {
    Ok(a.format == OutputFormat::Text)
}

/// The prior `--prior` (or `--prior-polygon`) and `--prior-heading` give,
/// checked.
fn prior_of(a: &Args) -> Result<Option<refloc::Prior>, CliError> {
    for (opt, v, n) in [
        ("--prior X,Y,R", &a.prior, 3),
        ("--prior-heading THETA,TOL", &a.prior_heading, 2),
    ] {
        if let Some(v) = v.as_ref().filter(|v| v.0.len() != n) {
            return Err(input_err(anyhow::anyhow!(
                "{opt} takes {n} comma-separated numbers, not {}",
                v.0.len()
            )));
        }
    }
    let mut prior = a
        .prior
        .as_ref()
        .map(|v| refloc::Prior::circle(v.0[0], v.0[1], v.0[2]));
    if let Some(polygon) = a.prior_polygon {
        prior = Some(refloc::Prior {
            polygon: Some(polygon),
            ..refloc::Prior::NONE
        });
    }
    if let Some(Numbers(h)) = &a.prior_heading {
        prior = Some(
            prior
                .unwrap_or(refloc::Prior::NONE)
                .with_heading(h[0].to_radians(), h[1].to_radians()),
        );
    }
    if prior.is_some_and(|p| !p.is_valid()) {
        return Err(input_err(anyhow::anyhow!(
            "--prior X,Y,R needs finite X, Y and R > 0 m; --prior-heading THETA,TOL a finite THETA and TOL >= 0 degrees"
        )));
    }
    Ok(prior)
}

/// Grows `scratch` (never shrinks it) to what a scan of `beams` beams
/// needs against a database with `params`.
fn grow_scratch(scratch: &mut Vec<u8>, params: &refloc::Params, beams: usize) {
    let need = scratch_size(params, beams);
    if scratch.len() < need {
        scratch.resize(need, 0);
    }
}

/// `mapc localize A.refdb B.refdb ... SCANS`: each scan against every
/// database; the answer is the accepted localization with the highest
/// confidence (its map, pose and confidence) if its probability among the
/// maps still reaches its map's threshold, or no map
/// (`refloc::select::which_map`, the rule the Python package uses too).
fn run_maps(a: &Args, ui: &Ui) -> CliResult {
    if a.truth.is_some()
        || a.mcap.is_some()
        || a.prior.is_some()
        || a.prior_polygon.is_some()
        || a.prior_heading.is_some()
    {
        return Err(input_err(anyhow::anyhow!(
            "--truth, --mcap, --prior, --prior-polygon and --prior-heading belong to one map; give one database with them, not {}",
            a.db.len()
        )));
    }
    let dbs =
        a.db.iter()
            .map(|p| open_db(p, Check::Full))
            .collect::<Result<Vec<_>, _>>()?;
    let names: Vec<String> = a.db.iter().map(|p| p.display().to_string()).collect();
    let text = output_is_text(a)?;
    let scans = scan_source(a, ui)?;
    let stdout = std::io::stdout();
    let mut out = Sink::new(stdout.lock(), is_stream(&a.input));
    let mut scratch: Vec<Vec<u8>> = vec![Vec::new(); dbs.len()];
    let (mut n, mut failed, mut none) = (0usize, 0usize, 0usize);
    let mut chosen = vec![0usize; dbs.len()];
    if text {
        out.line(&format!(
            "{:<12} {:<24} {:>4} {:>9} {:>9} {:>8} {:>6} {:>8}",
            "id", "map", "ok", "x_m", "y_m", "theta", "conf", "time_ms"
        ))?;
    }
    for item in scans {
        if out.closed {
            break;
        }
        n += 1;
        let scan = match item {
            Ok(s) => s,
            Err(e) => {
                failed += 1;
                out.line(&unreadable_line(&e, text))?;
                continue;
            }
        };
        let input = scan.data.as_scan();
        let t0 = Instant::now();
        // (map, accepted, confidence, pose) of every database that answered.
        let mut per_map = Vec::with_capacity(dbs.len());
        for (i, db) in dbs.iter().enumerate() {
            grow_scratch(&mut scratch[i], db.params(), scan.data.len());
            match refloc::localize(db, &input, &mut scratch[i]) {
                Ok(l) => per_map.push((i, l.accepted, l.confidence, l.pose, None)),
                Err(e) => {
                    per_map.push((i, false, 0.0, refloc::Pose2::default(), Some(e.to_string())))
                }
            }
        }
        let time_us = t0.elapsed().as_micros() as u64;
        let best = refloc::select::which_map(per_map.iter().map(|m| {
            let threshold = dbs[m.0]
                .decision()
                .unwrap_or(refloc::Decision::DEFAULT)
                .threshold;
            (m.1, m.2, threshold)
        }))
        .map(|i| &per_map[i]);
        match best {
            Some(b) => chosen[b.0] += 1,
            None => none += 1,
        }
        if text {
            let (map, ok, pose, conf) = match best {
                Some(b) => (names[b.0].as_str(), "yes", b.3, b.2),
                None => ("-", "no", refloc::Pose2::default(), 0.0),
            };
            out.line(&format!(
                "{:<12} {:<24} {:>4} {:>9.3} {:>9.3} {:>8.4} {:>6.3} {:>8.2}",
                scan.id,
                map,
                ok,
                pose.x,
                pose.y,
                pose.theta,
                conf,
                time_us as f64 / 1000.0
            ))?;
        } else {
            let mut o = json!({
                "id": scan.id,
                "accepted": best.is_some(),
                "map": best.map(|b| names[b.0].clone()),
                "map_index": best.map(|b| b.0),
                "x": best.map(|b| b.3.x), "y": best.map(|b| b.3.y), "theta": best.map(|b| b.3.theta),
                "confidence": best.map_or(0.0, |b| b.2),
                "time_us": time_us,
                "maps": per_map.iter().map(|m| {
                    let mut e = json!({"map": names[m.0], "accepted": m.1, "confidence": m.2,
                        "x": m.3.x, "y": m.3.y, "theta": m.3.theta});
                    if let Some(r) = &m.4 {
                        e["reason"] = json!(r);
                    }
                    e
                }).collect::<Vec<_>>(),
            });
            add_stamp(&mut o, &scan);
            out.line(&o.to_string())?;
        }
    }
    out.finish()?;
    if !ui.quiet {
        let per: Vec<String> = names
            .iter()
            .zip(&chosen)
            .map(|(m, c)| format!("{m}: {c}"))
            .collect();
        eprintln!(
            "{n} scans, {failed} unreadable; on which map: {}, none: {none}",
            per.join(", ")
        );
    }
    Ok(if failed > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}

/// `mapc localize`: each scan against the database (several databases:
/// [`run_maps`]), one result line a scan, then a summary on stderr.
pub fn run(a: Args, ui: &Ui) -> CliResult {
    if a.db.len() > 1 {
        return run_maps(&a, ui);
    }
    let db = open_db(&a.db[0], Check::Full)?;
    let text = output_is_text(&a)?;
    let prior = prior_of(&a)?;
    let truth = read_truth(&a)?;
    let scans = scan_source(&a, ui)?;
    let rec = match &a.mcap {
        Some(p) => Some(Recorder {
            rec: mapc::tools::recording::Recording::create(p)
                .map_err(|e| fail_err(anyhow::anyhow!("--mcap {}: {e}", p.display())))?,
            map_written: false,
        }),
        None => None,
    };
    let map = OneMap {
        a: &a,
        db: &db,
        text,
        prior,
        truth,
    };
    let stdout = std::io::stdout();
    let mut out = Sink::new(stdout.lock(), is_stream(&a.input));
    let mut session = Session {
        scratch: Vec::new(),
        rec,
        tally: Tally::default(),
        derived: Vec::new(),
    };
    if text {
        out.line(&format!(
            "{:<12} {:>4} {:>9} {:>9} {:>8} {:>6} {:>9} {:>8} {:>8} {:>6} {:>8}",
            "id", "ok", "x_m", "y_m", "theta", "site", "E", "M", "M_thr", "conf", "time_ms"
        ))?;
    }
    for (k, item) in scans.enumerate() {
        if out.closed {
            break;
        }
        session.tally.n += 1;
        let line = match item {
            Ok(scan) => session.localize(&map, k, &scan)?,
            Err(e) => {
                session.tally.failed += 1;
                unreadable_line(&e, text)
            }
        };
        out.line(&line)?;
    }
    out.finish()?;
    if let Some(r) = session.rec {
        r.rec.finish().map_err(rec_err)?;
    }
    let mut tally = session.tally;
    if out.closed {
        ui.note(&format!(
            "output closed by its reader after {} scans; stopped there",
            tally.n
        ));
    }
    if !ui.quiet {
        tally.print(!map.truth.is_empty());
    }
    Ok(if tally.failed > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}

/// `db` with its reference side made again for a sensor reaching `reach_m`
/// (`mapc::compiler::reach::derive_for_reach`, every early stop off), in
/// memory; the error says why it could not be made.
fn derive_db(db: &refloc::RefDb<DbBytes>, reach_m: f32) -> Result<refloc::RefDb<DbBytes>, String> {
    let fail = |e: String| format!("reference scans for a {reach_m:.1} m reach: {e}");
    let sections = mapc::compiler::reach::derive_for_reach(db, reach_m, true)
        .map_err(|e| fail(e.to_string()))?;
    let (words, len) = mapc::compiler::reach::encode_aligned(&sections);
    refloc::RefDb::new(DbBytes::Owned { words, len }).map_err(|e| fail(e.to_string()))
}

/// `--truth`: the given robot poses by scan index (none without it).
fn read_truth(a: &Args) -> Result<HashMap<usize, [f64; 3]>, CliError> {
    Ok(match &a.truth {
        Some(p) => scanio::read_poses_in_map(p)
            .map_err(|e| input_err(anyhow::anyhow!("{}: {e}", p.display())))?
            .into_iter()
            .collect(),
        None => HashMap::new(),
    })
}

/// A `--mcap` write error.
fn rec_err(e: anyhow::Error) -> CliError {
    fail_err(anyhow::anyhow!("--mcap: {e}"))
}

/// What localizing a scan against the one database takes, fixed for the
/// run: the options, the database, the output format, the prior and the
/// given truth poses.
struct OneMap<'a> {
    a: &'a Args,
    db: &'a refloc::RefDb<DbBytes>,
    text: bool,
    prior: Option<refloc::Prior>,
    truth: HashMap<usize, [f64; 3]>,
}

/// What changes from scan to scan: the localizer's scratch space, the
/// `--mcap` recording and the counts for the summary.
struct Session {
    scratch: Vec<u8>,
    rec: Option<Recorder>,
    tally: Tally,
    /// Databases derived for a shorter reach (`mapc::compiler::reach`), by
    /// the reach in decimetres ([`derived_reach_dm`]); `None` where the
    /// derivation failed (the database's own is used). At most
    /// [`MAX_DERIVED`], the oldest dropped first.
    derived: Vec<(u32, Option<refloc::RefDb<DbBytes>>)>,
}

/// Most databases derived for other reaches a run keeps at once (each is
/// about the database's size in memory).
const MAX_DERIVED: usize = 4;

/// The reach (decimetres) of the reference scans made for a scan reaching
/// `reach` m: rounded down to 0.1 m, so that a run whose scans state many
/// slightly different reaches derives a few sets, not one per scan.
fn derived_reach_dm(reach: f32) -> u32 {
    (reach * 10.0 + 1e-3).floor().clamp(0.0, u32::MAX as f32) as u32
}

impl Session {
    /// Localizes scan `k` of the input against `map`, records it
    /// (`--mcap`), counts it and returns its output line.
    fn localize(
        &mut self,
        map: &OneMap<'_>,
        k: usize,
        scan: &scanio::InputScan,
    ) -> Result<String, CliError> {
        let reach = scan.data.range_max();
        let reference = map.db.params().sensor.range_max;
        let short = refloc::localize::is_short_reach(reach, reference);
        if short {
            let t = &mut self.tally;
            t.shortest_reach = if t.short_reach == 0 {
                reach
            } else {
                t.shortest_reach.min(reach)
            };
            t.short_reach += 1;
            t.reference_reach = reference;
        }
        let db = if short && !map.a.database_reach {
            let key = derived_reach_dm(reach);
            let i = match self.derived.iter().position(|(k, _)| *k == key) {
                Some(i) => i,
                None => {
                    if self.derived.len() >= MAX_DERIVED {
                        self.derived.remove(0);
                    }
                    let made = derive_db(map.db, key as f32 / 10.0);
                    if let Err(e) = &made {
                        self.tally.derive_failed = Some(e.to_string());
                    }
                    self.derived.push((key, made.ok()));
                    self.derived.len() - 1
                }
            };
            match &self.derived[i].1 {
                Some(d) => {
                    self.tally.derived += 1;
                    d
                }
                None => map.db,
            }
        } else {
            map.db
        };
        grow_scratch(&mut self.scratch, db.params(), scan.data.len());
        let input = scan.data.as_scan();
        let t0 = Instant::now();
        let r = refloc::localize_with_prior(db, &input, &mut self.scratch, map.prior);
        let time_us = t0.elapsed().as_micros() as u64;
        if let Some(rec) = self.rec.as_mut() {
            rec.record(db, k, scan, &r)?;
        }
        self.tally.times.push(time_us as f64);
        let judged = map.judge(k, scan);
        Ok(match r {
            Ok(l) => {
                let err = judged
                    .as_ref()
                    .map(|j| mapc::tools::eval::pose_error(&l.pose, j.truth));
                self.tally.count(&l, judged.as_ref(), err);
                let found = Found {
                    scan,
                    l: &l,
                    time_us,
                    err,
                    judged: judged.as_ref(),
                };
                if map.text {
                    found.text_line()
                } else {
                    found.json_line(map.a.no_candidates)
                }
            }
            // A scan that cannot be localized is a result, not a failed line.
            Err(e) => {
                if map.text {
                    format!("{:<12} {:>4} not localized: {e}", scan.id, "no")
                } else {
                    let mut o = json!({"id": scan.id, "accepted": false, "reason": e.to_string(), "time_us": time_us});
                    add_stamp(&mut o, scan);
                    o.to_string()
                }
            }
        })
    }
}

/// The `--mcap` recording, and whether the map is in it yet.
struct Recorder {
    rec: mapc::tools::recording::Recording,
    map_written: bool,
}

impl Recorder {
    /// Records scan `k` and its localization `r`: the map (at the first
    /// readable scan's time), the scan, the hypotheses, and when accepted
    /// the pose and the transform to the sensor frame.
    fn record(
        &mut self,
        db: &refloc::RefDb<DbBytes>,
        k: usize,
        scan: &scanio::InputScan,
        r: &Result<refloc::Localization<'_>, refloc::LocalizeError>,
    ) -> Result<(), CliError> {
        let rec = &mut self.rec;
        let at_ns = scan.stamp.as_ref().map_or(k as i64 * 100_000_000, |s| s.ns);
        let frame_id = scan
            .stamp
            .as_ref()
            .map(|s| s.frame_id.as_str())
            .filter(|f| !f.is_empty())
            .unwrap_or("laser");
        let at = mapc::tools::recording::Stamp {
            ns: at_ns,
            frame: frame_id,
        };
        if !self.map_written {
            // At the first readable scan's time.
            rec.map(at_ns, &db.frame(), &db.grid()).map_err(rec_err)?;
            self.map_written = true;
        }
        if let ScanData::Ranges {
            angle_min,
            angle_increment,
            range_min,
            range_max,
            ranges,
        } = &scan.data
        {
            rec.scan(
                &at,
                *angle_min,
                *angle_increment,
                *range_min,
                *range_max,
                ranges,
            )
            .map_err(rec_err)?;
        }
        if let Ok(l) = r {
            let hyps: Vec<refloc::Pose2> = l.hypotheses().iter().map(|h| h.pose).collect();
            rec.hypotheses(at_ns, &hyps).map_err(rec_err)?;
            if l.accepted {
                rec.pose(at_ns, &l.pose, l.covariance).map_err(rec_err)?;
                rec.tf(&at, &l.pose.compose(&db.params().sensor.offset))
                    .map_err(rec_err)?;
            }
        }
        Ok(())
    }
}

/// A scan's given truth pose (`--truth`) and how well it, and it corrected
/// against the map, explain the scan.
struct Judged {
    /// The given robot pose `[x (m), y (m), theta (rad)]`.
    truth: [f64; 3],
    /// The vicinity ratio (M / max) of the scan at the truth's sensor pose:
    /// a low value means the truth and the map disagree there.
    fit: f64,
    /// The truth corrected locally against the map with the scan's own
    /// points (a search near the truth pose, then a fit): where the map
    /// puts the scan near the truth. A second reference for the figures
    /// where the truth and the map disagree.
    refined: refloc::Pose2,
    /// The vicinity ratio at `refined`'s sensor pose.
    refined_fit: f64,
}

impl OneMap<'_> {
    /// The truth of scan `k` judged against the scan and the map, when
    /// there is one. The truth index is the scan's position among the
    /// laser lines.
    fn judge(&self, k: usize, scan: &scanio::InputScan) -> Option<Judged> {
        let db = self.db;
        let scan_index = scan
            .id
            .strip_prefix("scan ")
            .and_then(|s| s.parse().ok())
            .unwrap_or(k);
        let truth = self.truth.get(&scan_index).copied()?;
        // The scan's beams as (angle in the sensor frame (rad), range (m)),
        // non-returns infinite.
        let beams = scan.data.beams();
        let rmax = scan.data.range_max();
        let offset = &db.params().sensor.offset;
        let sensor =
            refloc::Pose2::new(truth[0] as f32, truth[1] as f32, truth[2] as f32).compose(offset);
        // How well a sensor pose explains the scan (M / max).
        let fit = |sensor: &refloc::Pose2| {
            let grid = db.grid();
            let v =
                refloc::verify::Verifier::new(db, &grid, rmax).score(sensor, beams.iter().copied());
            v.vicinity_ratio() as f64
        };
        let truth_fit = fit(&sensor);
        let refined = mapc::tools::eval::correct_truth_locally(db, &beams, sensor);
        Some(Judged {
            truth,
            fit: truth_fit,
            refined,
            refined_fit: fit(&refined.compose(offset)),
        })
    }
}

/// A localized scan, for its output line.
struct Found<'a, 's> {
    scan: &'a scanio::InputScan,
    l: &'a refloc::Localization<'s>,
    time_us: u64,
    /// Position (m) and heading (rad) error against the truth, if given.
    err: Option<(f64, f64)>,
    judged: Option<&'a Judged>,
}

impl Found<'_, '_> {
    /// The `--format text` row.
    fn text_line(&self) -> String {
        let (scan, l) = (self.scan, self.l);
        format!(
            "{:<12} {:>4} {:>9.3} {:>9.3} {:>8.4} {:>6} {:>9.1} {:>8.1} {:>8.1} {:>6.3} {:>8.2}{}",
            scan.id,
            if l.accepted { "yes" } else { "no" },
            l.pose.x,
            l.pose.y,
            l.pose.theta,
            l.site,
            l.match_score,
            l.vicinity,
            l.vicinity_threshold,
            l.confidence,
            self.time_us as f64 / 1000.0,
            self.err
                .map(|(e, t)| format!("  err {:.3} m {:.2} deg", e, t.to_degrees()))
                .unwrap_or_default()
        )
    }

    /// The `--format json` object (candidates only counted with
    /// `no_candidates`).
    fn json_line(&self, no_candidates: bool) -> String {
        let (scan, l) = (self.scan, self.l);
        let mut o = json!({
            "id": scan.id, "accepted": l.accepted,
            "x": l.pose.x, "y": l.pose.y, "theta": l.pose.theta,
            "site": l.site, "coarse_rank": l.coarse_rank, "gamma": l.gamma,
            "match_score": l.match_score, "inliers": l.inliers,
            "vicinity": l.vicinity, "vicinity_threshold": l.vicinity_threshold,
            "valid_points": l.valid_points, "short_beams": l.short_beams, "long_beams": l.long_beams, "through_beams": l.through_beams,
            "evidence": l.evidence, "free_space_ok": l.free_space_ok,
            "ambiguous": l.ambiguous, "time_us": self.time_us,
            "confidence": l.confidence, "skew": l.skew,
            "covariance": l.covariance,
            "hypotheses": l.hypotheses().iter()
                .map(|h| json!({"x": h.pose.x, "y": h.pose.y, "theta": h.pose.theta, "confidence": h.confidence}))
                .collect::<Vec<_>>(),
        });
        add_stamp(&mut o, scan);
        if no_candidates {
            o["candidates"] = json!(l.candidates.len());
        } else {
            o["candidates"] = l
                .candidates
                .iter()
                .map(|c| json!({"site": c.site, "rank": c.rank, "gamma": c.gamma, "match_score": c.match_score,
                    "has_pose": c.has_pose != 0, "x": c.x, "y": c.y, "theta": c.theta, "vicinity": c.vicinity,
                    "evidence": c.evidence, "free_space_ok": c.free_space_ok != 0, "short_beams": c.short_beams, "pairs": c.pairs,
                    "through_beams": c.through_beams, "long_beams": c.long_beams, "spread": c.spread}))
                .collect();
        }
        if let (Some((e, et)), Some(j)) = (self.err, self.judged) {
            o["truth"] = json!(j.truth);
            o["error_m"] = json!(e);
            o["error_rad"] = json!(et);
            o["truth_vicinity_ratio"] = json!(j.fit);
            let r = j.refined;
            o["truth_refined"] = json!([r.x, r.y, r.theta]);
            o["truth_refined_vicinity_ratio"] = json!(j.refined_fit);
        }
        o.to_string()
    }
}

/// The counts and figures of the stderr summary.
#[derive(Default)]
struct Tally {
    /// Input items (scans and unreadable lines).
    n: usize,
    failed: usize,
    accepted: usize,
    /// Against the given truth: accepted and within the tolerance.
    correct: usize,
    /// Against the given truth: accepted and not within the tolerance.
    false_acc: usize,
    /// False accepts where the truth explains the scan much worse.
    false_acc_truth_fits_worse: usize,
    /// False accepts whose corrected truth lands on the estimate.
    false_acc_truth_refines_to_ours: usize,
    /// Accepted and within the tolerance of the corrected truth.
    correct_refined: usize,
    /// Accepted and not within the tolerance of the corrected truth.
    false_acc_refined: usize,
    /// Position errors (m) of the correct estimates.
    errs: Vec<f64>,
    /// Localization times (µs).
    times: Vec<f64>,
    /// Scans whose sensor reaches less than `refloc::localize::SHORT_REACH`
    /// of the reference range, and the shortest reach among them (m).
    short_reach: usize,
    shortest_reach: f32,
    /// The database's reference range (m).
    reference_reach: f32,
    /// Of those, the scans localized on reference scans made for their
    /// reach (not `--database-reach`).
    derived: usize,
    /// Why reference scans for some reach could not be made (those scans
    /// were localized on the database's own).
    derive_failed: Option<String>,
}

impl Tally {
    /// Counts localization `l`, judged against the truth and its
    /// correction (`err`: the error against the truth).
    fn count(
        &mut self,
        l: &refloc::Localization<'_>,
        judged: Option<&Judged>,
        err: Option<(f64, f64)>,
    ) {
        if l.accepted {
            self.accepted += 1;
        }
        // Within the tolerance of the corrected truth.
        let ok_refined = judged.map(|j| {
            let r = j.refined;
            mapc::tools::eval::within_tolerance(&l.pose, [r.x as f64, r.y as f64, r.theta as f64])
        });
        if let (Some(ok), true) = (ok_refined, l.accepted) {
            if ok {
                self.correct_refined += 1;
            } else {
                self.false_acc_refined += 1;
            }
        }
        let Some(j) = judged else {
            return;
        };
        if l.accepted && mapc::tools::eval::within_tolerance(&l.pose, j.truth) {
            self.correct += 1;
            self.errs.extend(err.map(|(e, _)| e));
        } else if l.accepted {
            self.false_acc += 1;
            let ours = refloc::verify::ratio(l.vicinity, l.valid_points) as f64;
            if j.fit < ours - 0.2 {
                self.false_acc_truth_fits_worse += 1;
            }
            // Where does the given truth go when it is corrected against the
            // map? Onto the estimate means the map puts the scan where we did.
            if ok_refined == Some(true) {
                self.false_acc_truth_refines_to_ours += 1;
            }
        }
    }

    /// The summary on stderr (the comparison with the truth when
    /// `with_truth`).
    fn print(&mut self, with_truth: bool) {
        let n = self.n;
        self.times.sort_by(|a, b| a.total_cmp(b));
        let med_t = self.times.get(self.times.len() / 2).copied().unwrap_or(0.0);
        eprintln!(
            "{n} scans, {} unreadable, {} accepted, median {:.1} ms/scan",
            self.failed,
            self.accepted,
            med_t / 1000.0
        );
        if let Some(e) = &self.derive_failed {
            eprintln!(
                "warning: {e}; those scans were localized on the database's own reference scans"
            );
        }
        if self.derived > 0 {
            eprintln!(
                "note: {} scans come from a sensor that reaches {:.1} m or less, under half the {:.1} m of the database's reference scans: {} were localized on reference scans made again for their reach from the database (`--database-reach` uses its own); `mapc build --range-max {:.1}` stores them (docs/robot.md, \"Sensor reach\")",
                self.short_reach,
                self.shortest_reach,
                self.reference_reach,
                self.derived,
                self.shortest_reach
            );
        } else if self.short_reach > 0 {
            eprintln!(
                "note: {} scans come from a sensor that reaches {:.1} m or less, under half the {:.1} m of the database's reference scans: every candidate is examined for them (slower), and a database built for that sensor answers them better: `mapc build --range-max {:.1}` (docs/robot.md, \"Sensor reach\")",
                self.short_reach,
                self.shortest_reach,
                self.reference_reach,
                self.shortest_reach
            );
        }
        if !with_truth {
            return;
        }
        self.errs.sort_by(|a, b| a.total_cmp(b));
        let med = self
            .errs
            .get(self.errs.len() / 2)
            .copied()
            .unwrap_or(f64::NAN);
        let pct = |c: usize| 100.0 * c as f64 / n.max(1) as f64;
        eprintln!(
            "against truth: accepted and correct {} ({:.1}%), false accepts {} ({:.1}%), median position error {:.3} m",
            self.correct,
            pct(self.correct),
            self.false_acc,
            pct(self.false_acc),
            med
        );
        eprintln!(
            "  of the false accepts, {} are where the given truth pose explains the scan much worse than the estimate (vicinity ratio lower by > 0.2): truth and map disagree there",
            self.false_acc_truth_fits_worse
        );
        eprintln!(
            "  against the given truth refined against the map (search within 0.5 m and 15 deg of the truth pose, then robust Gauss-Newton): accepted and correct {} ({:.1}%), false accepts {} ({:.1}%)",
            self.correct_refined,
            pct(self.correct_refined),
            self.false_acc_refined,
            pct(self.false_acc_refined),
        );
        eprintln!(
            "  of the false accepts, {} have a given truth that, refined against the map (search within 0.5 m and 15 deg of the truth pose, then robust Gauss-Newton), lands within 0.3 m / 5 deg of the estimate",
            self.false_acc_truth_refines_to_ours
        );
    }
}

#[cfg(test)]
mod tests {
    use super::derived_reach_dm;

    #[test]
    fn a_derived_reach_is_the_scans_rounded_down_to_a_decimetre() {
        assert_eq!(derived_reach_dm(4.0), 40);
        assert_eq!(derived_reach_dm(3.5), 35);
        assert_eq!(derived_reach_dm(5.6), 56);
        assert_eq!(derived_reach_dm(5.69), 56);
        assert_eq!(derived_reach_dm(0.05), 0);
        assert_eq!(derived_reach_dm(f32::NAN), 0);
        assert_eq!(derived_reach_dm(-3.0), 0);
    }
}
