//! `mapc eval`: the paper's experiments on simulated scans, a JSON report,
//! PNG figures, and the CI regression check.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;

use mapc::compiler::rng::Rng;
use mapc::tools::eval::{self, ScanSpec, Summary, Tolerance, Trial};
use mapc::tools::figures;
use serde_json::{json, Value};

use crate::util::outln;
use crate::util::{fail_err, input_err, open_db, read_aux_text, Check, CliResult, Ui};

/// One value of `mapc eval --experiments`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Experiment {
    /// E4 with noise-free scans.
    Static,
    /// E4 with range noise and random short returns (`--noise`, `--outliers`).
    Dynamic,
    /// E4 with range noise and beams swapped pairwise.
    DynamicSwap,
    /// E1: scan-to-scan SSM accuracy (Table 1).
    E1,
    /// E2: robustness curves (Fig. 6).
    E2,
    /// Scans of another map (`--foreign`) that must not be accepted.
    WrongMap,
    /// Every class of the disturbance suite.
    Disturbances,
    /// One class of the disturbance suite.
    Disturbance(mapc::tools::disturb::Class),
}

impl Experiment {
    const PAPER: [Experiment; 7] = [
        Experiment::Static,
        Experiment::Dynamic,
        Experiment::DynamicSwap,
        Experiment::E1,
        Experiment::E2,
        Experiment::WrongMap,
        Experiment::Disturbances,
    ];
    /// Every value, the disturbance classes in `disturb::Class::ALL` order.
    const ALL: [Experiment; Self::PAPER.len() + mapc::tools::disturb::Class::ALL.len()] = {
        let mut all =
            [Experiment::Static; Self::PAPER.len() + mapc::tools::disturb::Class::ALL.len()];
        let mut i = 0;
        while i < Self::PAPER.len() {
            all[i] = Self::PAPER[i];
            i += 1;
        }
        let mut k = 0;
        while k < mapc::tools::disturb::Class::ALL.len() {
            all[i + k] = Experiment::Disturbance(mapc::tools::disturb::Class::ALL[k]);
            k += 1;
        }
        all
    };

    /// The name on the command line and in the report.
    pub fn name(self) -> &'static str {
        match self {
            Experiment::Static => "static",
            Experiment::Dynamic => "dynamic",
            Experiment::DynamicSwap => "dynamic-swap",
            Experiment::E1 => "e1",
            Experiment::E2 => "e2",
            Experiment::WrongMap => "wrong-map",
            Experiment::Disturbances => "disturbances",
            Experiment::Disturbance(c) => c.name(),
        }
    }
}

impl clap::ValueEnum for Experiment {
    fn value_variants<'a>() -> &'a [Self] {
        &Self::ALL
    }
    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.name()))
    }
}

#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// The database.
    pub db: PathBuf,
    /// Random poses for E4 (and E5) (1 to 1000000: each trial keeps a
    /// record of a few hundred bytes, so this bounds the report's memory).
    #[arg(long, default_value_t = 1000, value_parser = crate::util::count::<1, 1_000_000>)]
    pub poses: usize,
    /// Seed of every random choice.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Poses keep at least this distance from obstacles (m).
    #[arg(long, default_value_t = 0.3, value_name = "M")]
    pub clearance: f32,
    /// Beams of the simulated scans (3 to 100000: the runtime is tested with
    /// 100,000-beam scans).
    #[arg(long, default_value_t = 362, value_parser = crate::util::count::<3, 100_000>)]
    pub beams: usize,
    /// Field of view of the simulated scans (degrees).
    #[arg(long, default_value_t = 360.0, value_name = "DEG")]
    pub fov: f32,
    /// Maximum range of the simulated scans (m).
    #[arg(long, default_value_t = 30.0, value_name = "M")]
    pub range_max: f32,
    /// Range noise sigma of the dynamic runs (m).
    #[arg(long, default_value_t = 0.005, value_name = "M")]
    pub noise: f32,
    /// Outliers per scan in the dynamic runs (random short returns; and x-y swaps in dynamic-swap).
    #[arg(long, default_value_t = 60)]
    pub outliers: usize,
    /// Experiments to run, comma separated: the paper's (static, dynamic,
    /// dynamic-swap, e1, e2, wrong-map) and the disturbance suite, one class
    /// at a time or `disturbances` for all of them (docs/results.md).
    #[arg(
        long,
        value_enum,
        default_values = ["static", "dynamic", "dynamic-swap", "e1"],
        value_delimiter = ','
    )]
    pub experiments: Vec<Experiment>,
    /// E4 runs with a prior region of this radius (m) around each true pose
    /// (its centre moved by up to half the radius; 0: no region).
    #[arg(long, default_value_t = 0.0, value_name = "M")]
    pub prior_radius: f32,
    /// E4 runs with a prior heading window of +- this (degrees) around each
    /// true heading (moved by up to half of it; 0: no window).
    #[arg(long, default_value_t = 0.0, value_name = "DEG")]
    pub prior_heading_tol: f32,
    /// E1 trials (paper: 500; 1 to 1000000).
    #[arg(long, default_value_t = 500, value_parser = crate::util::count::<1, 1_000_000>)]
    pub e1_trials: usize,
    /// E2 trials per point (paper: 30; 1 to 1000000).
    #[arg(long, default_value_t = 30, value_parser = crate::util::count::<1, 1_000_000>)]
    pub e2_trials: usize,
    /// For wrong-map: the other map (YAML) whose scans are localized against this database.
    #[arg(long, value_name = "MAP.yaml")]
    pub foreign: Option<PathBuf>,
    /// Directory for report.json and figures.
    #[arg(long, default_value = "build-artifacts/eval", value_name = "DIR")]
    pub out: PathBuf,
    /// Skip the PNG figures.
    #[arg(long)]
    pub no_figures: bool,
    /// Also write the simulated inputs to DIR, for running other tools on
    /// the same data: `<run>-scans.jsonl` (one LaserScan JSON line per E4
    /// pose, readable by `mapc localize`) and `<run>-truth.txt` (the true
    /// poses, for `--truth`) for each E4 run, and `e1-pairs.jsonl` (each E1
    /// pair's points, true motion and this run's SSM error and time).
    #[arg(long, value_name = "DIR")]
    pub dump: Option<PathBuf>,
    /// Baseline report: exit 1 when this run is worse by more than the tolerances.
    #[arg(long, value_name = "BASELINE.json")]
    pub check: Option<PathBuf>,
    /// Allowed drop of a success rate (absolute fraction).
    #[arg(long, default_value_t = 0.02)]
    pub tol_rate: f64,
    /// Allowed rise of a false-accept rate (absolute fraction).
    #[arg(long, default_value_t = 0.01)]
    pub tol_false_accept: f64,
    /// Allowed growth factor of mean errors.
    #[arg(long, default_value_t = 1.5)]
    pub tol_error_factor: f64,
    #[command(flatten)]
    pub limits: crate::build::MapLimitArgs,
}

fn fmt_summary(name: &str, s: &Summary) -> String {
    format!(
        "{name:<14} n {:>5}  ok {:>6.2}%  false-acc {:>5.2}%  mean |x| {:>6.1} mm |y| {:>6.1} mm |th| {:>5.2} deg  max {:>6.1}/{:>6.1} mm {:>5.2} deg  med {:>5.1} mm  recall {:>6.2}%  {:>7.2} ms/query",
        s.n,
        100.0 * s.success_rate,
        100.0 * s.false_accept_rate,
        1000.0 * s.mean_abs_x,
        1000.0 * s.mean_abs_y,
        s.mean_abs_theta.to_degrees(),
        1000.0 * s.max_abs[0],
        1000.0 * s.max_abs[1],
        s.max_abs[2].to_degrees(),
        1000.0 * s.median_pos,
        100.0 * s.correct_site_recall,
        s.median_time_us / 1000.0
    )
}

pub fn run(a: Args, ui: &Ui) -> CliResult {
    // The baseline is read before the evaluation, so a bad one fails fast.
    let baseline = match &a.check {
        Some(base) => Some(read_aux_text(base, "--check")?),
        None => None,
    };
    // The output directory and its report must be writable places, checked
    // before minutes of evaluation.
    if a.out.exists() && !a.out.is_dir() {
        return Err(input_err(anyhow::anyhow!(
            "--out {}: not a directory",
            a.out.display()
        )));
    }
    let report_path = a.out.join("report.json");
    let mut inputs: Vec<&std::path::Path> = vec![&a.db];
    inputs.extend(a.check.as_deref());
    mapc::compiler::writer::check_output_path(&report_path, &inputs)
        .map_err(|e| input_err(anyhow::anyhow!("{}: {e}", report_path.display())))?;
    let report = evaluate(&a, ui)?;
    std::fs::create_dir_all(&a.out)
        .map_err(|e| fail_err(anyhow::anyhow!("{}: {e}", a.out.display())))?;
    std::fs::write(
        &report_path,
        serde_json::to_string_pretty(&report).unwrap_or_default(),
    )
    .map_err(|e| fail_err(anyhow::anyhow!("{}: {e}", report_path.display())))?;
    ui.note(&format!("report: {}", report_path.display()));
    if let (Some(base), Some(text)) = (&a.check, baseline) {
        let b: Value = serde_json::from_str(&text)
            .map_err(|e| input_err(anyhow::anyhow!("{}: not a report: {e}", base.display())))?;
        let parse = |v: &Value| -> Vec<(String, Summary)> {
            v["summaries"]
                .as_object()
                .map(|m| {
                    m.iter()
                        .filter_map(|(k, s)| {
                            Some((k.clone(), serde_json::from_value(s.clone()).ok()?))
                        })
                        .collect()
                })
                .unwrap_or_default()
        };
        let tol = Tolerance {
            rate: a.tol_rate,
            false_accept: a.tol_false_accept,
            error_factor: a.tol_error_factor,
            ..Tolerance::default()
        };
        let base_s = parse(&b);
        if base_s.is_empty() {
            return Err(input_err(anyhow::anyhow!(
                "{}: baseline has no summaries",
                base.display()
            )));
        }
        let regs = eval::check(&parse(&report), &base_s, &tol);
        if regs.is_empty() {
            outln!("check: no regression against {} (tolerances: rate {:.3}, false-accept {:.3}, error x{:.2})", base.display(), tol.rate, tol.false_accept, tol.error_factor);
        } else {
            for r in &regs {
                outln!(
                    "REGRESSION {}: baseline {:.6}, now {:.6}, limit {:.6}",
                    r.metric,
                    r.baseline,
                    r.current,
                    r.limit
                );
            }
            return Ok(ExitCode::from(1));
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// Refuses what the command line's own bounds (`util::count` on `--beams`,
/// `--poses` and the trial counts) cannot: outliers past the beam count, and
/// a range that is not a positive number of metres.
fn check_counts(a: &Args) -> Result<(), crate::util::CliError> {
    if a.outliers > a.beams {
        return Err(input_err(anyhow::anyhow!(
            "--outliers must be between 0 and {}, not {}",
            a.beams,
            a.outliers
        )));
    }
    if !(a.range_max.is_finite() && a.range_max > 0.0) {
        return Err(input_err(anyhow::anyhow!(
            "--range-max must be a positive number of metres, not {}",
            a.range_max
        )));
    }
    Ok(())
}

/// Runs the requested experiments and returns the report.
pub fn evaluate(a: &Args, ui: &Ui) -> Result<Value, crate::util::CliError> {
    check_counts(a)?;
    let db = open_db(&a.db, Check::Full)?;
    let fov = a.fov.to_radians();
    if !(fov > 0.0 && fov <= 2.0 * std::f32::consts::PI + 1e-3) {
        return Err(input_err(anyhow::anyhow!(
            "--fov must be in (0, 360] degrees, not {}",
            a.fov
        )));
    }
    let ev = Evaluation { a, ui, db, fov };
    let poses = eval::sample_poses(&ev.db, a.poses, a.clearance, a.seed);
    if poses.is_empty() {
        return Err(input_err(anyhow::anyhow!(
            "no free cell with clearance {} m to sample poses from",
            a.clearance
        )));
    }
    let mut report = Report {
        json: json!({
            "db": a.db.display().to_string(),
            "config": {"poses": a.poses, "seed": a.seed, "clearance_m": a.clearance, "beams": a.beams, "fov_deg": a.fov,
                       "range_max_m": a.range_max, "noise_m": a.noise, "outliers": a.outliers},
            "sites": ev.db.site_count(),
        }),
        summaries: BTreeMap::new(),
    };
    for (name, sp) in ev.e4_runs() {
        ev.e4(name, &sp, &poses, &mut report)?;
    }
    if ev.want(Experiment::WrongMap) {
        ev.wrong_map(&mut report)?;
    }
    if ev.want(Experiment::E1) {
        ev.e1(&mut report)?;
    }
    if ev.want(Experiment::E2) {
        ev.e2(&mut report);
    }
    Ok(report.finish())
}

/// The report of a run as it is assembled: the JSON object and the
/// summaries of the runs that have one, keyed by run name (they go in as
/// `summaries` at the end, the part `--check` compares).
struct Report {
    json: Value,
    summaries: BTreeMap<String, Value>,
}

impl Report {
    /// Records the summary of run `name`.
    fn summary(&mut self, name: &str, s: &Summary) {
        self.summaries.insert(
            name.to_string(),
            serde_json::to_value(s).unwrap_or(Value::Null),
        );
    }

    /// The complete report.
    fn finish(mut self) -> Value {
        self.json["summaries"] = serde_json::to_value(&self.summaries).unwrap_or(Value::Null);
        self.json
    }
}

/// One `mapc eval` run: its arguments, the database and the checked field
/// of view (rad). Each experiment is a method that adds its part to the
/// [`Report`].
struct Evaluation<'a> {
    a: &'a Args,
    ui: &'a Ui,
    db: refloc::RefDb<crate::util::DbBytes>,
    fov: f32,
}

impl Evaluation<'_> {
    /// Whether experiment `e` was asked for (`disturbances` asks for every
    /// disturbance class).
    fn want(&self, e: Experiment) -> bool {
        self.a.experiments.contains(&e)
            || (matches!(e, Experiment::Disturbance(_))
                && self.a.experiments.contains(&Experiment::Disturbances))
    }

    /// The simulated scans of the arguments with range noise `noise` (m),
    /// `short` random short returns and `swap` swapped beam pairs.
    fn spec(&self, noise: f32, short: usize, swap: usize) -> ScanSpec {
        let a = self.a;
        ScanSpec {
            beams: a.beams,
            fov: self.fov,
            range_max: a.range_max,
            noise,
            short_outliers: short,
            swap_outliers: swap,
            disturbance: None,
            prior_radius: a.prior_radius,
            prior_heading_tol: a.prior_heading_tol.to_radians(),
        }
    }

    /// The requested E4 runs, by name, in report order: static, dynamic,
    /// dynamic-swap, then the disturbance classes.
    fn e4_runs(&self) -> Vec<(&'static str, ScanSpec)> {
        let a = self.a;
        [
            (Experiment::Static, self.spec(0.0, 0, 0)),
            (Experiment::Dynamic, self.spec(a.noise, a.outliers, 0)),
            (Experiment::DynamicSwap, self.spec(a.noise, 0, a.outliers)),
        ]
        .into_iter()
        .chain(mapc::tools::disturb::Class::ALL.map(|c| {
            (
                Experiment::Disturbance(c),
                ScanSpec {
                    disturbance: Some(c),
                    ..self.spec(0.0, 0, 0)
                },
            )
        }))
        .filter(|&(e, _)| self.want(e))
        .map(|(e, sp)| (e.name(), sp))
        .collect()
    }

    /// E4 (and E5) run `name`: localizes a scan `sp` at each of `poses`,
    /// dumps the inputs (`--dump`), draws the figures and reports the
    /// summary and the statistics of [`e4_statistics`].
    fn e4(
        &self,
        name: &str,
        sp: &ScanSpec,
        poses: &[refloc::Pose2],
        report: &mut Report,
    ) -> Result<(), crate::util::CliError> {
        let a = self.a;
        if let Some(dir) = &a.dump {
            dump_e4(&self.db, poses, sp, a.seed, dir, name)?;
        }
        let pb = self.ui.progress(poses.len() as u64, name);
        let tick = || pb.inc(1);
        let trials = eval::run_e4(&self.db, poses, sp, a.seed, None, &tick);
        pb.finish_and_clear();
        let s = eval::summarize(&trials);
        self.ui.note(&fmt_summary(name, &s));
        if !a.no_figures {
            self.e4_figures(name, &trials);
        }
        e4_statistics(name, &trials, &mut report.json);
        report.summary(name, &s);
        Ok(())
    }

    /// The figures of E4 run `name` (a warning when they cannot be written).
    fn e4_figures(&self, name: &str, trials: &[Trial]) {
        let out = &self.a.out;
        let _ = std::fs::create_dir_all(out);
        let f = |n: &str| out.join(format!("{name}-{n}.png"));
        let r = figures::poses_figure(
            &self.db,
            trials,
            &format!("E4 {name}: true vs estimated poses"),
            300,
            &f("poses"),
        )
        .and_then(|_| {
            figures::error_figure(
                trials,
                &format!("E4 {name}: pose errors (Fig. 12)"),
                &f("errors"),
            )
        })
        .and_then(|_| {
            figures::rank_figure(
                trials,
                &format!("E5 {name}: coarse rank of the correct site (Fig. 16)"),
                &f("ranks"),
            )
        });
        if let Err(e) = r {
            self.ui.note(&format!("warning: figures not written: {e}"));
        }
    }

    /// The wrong-map run: scans simulated in the `--foreign` map, none of
    /// which may be accepted.
    fn wrong_map(&self, report: &mut Report) -> Result<(), crate::util::CliError> {
        let a = self.a;
        let Some(fp) = &a.foreign else {
            return Err(input_err(anyhow::anyhow!(
                "wrong-map needs --foreign MAP.yaml"
            )));
        };
        let src = crate::build::load_map(fp, None, None, &a.limits).map_err(input_err)?;
        let g = &src.grid;
        let bits = g.blocked_bits(true);
        let bg = refloc::raycast::BitGrid::new(g.width, g.height, &bits)
            .ok_or_else(|| input_err(anyhow::anyhow!("grid")))?;
        let frame = g.frame();
        let df = mapc::compiler::edt::DistanceField::from_grid(g, true);
        let fposes = eval::sample_poses_where(
            g.width,
            g.height,
            &frame,
            |i| df.clearance_m(i) >= a.clearance as f64,
            a.poses,
            a.seed ^ 0xF0,
        );
        let pb = self.ui.progress(fposes.len() as u64, "wrong-map");
        let tick = || pb.inc(1);
        let trials = eval::run_e4(
            &self.db,
            &fposes,
            &self.spec(0.0, 0, 0),
            a.seed,
            Some((&bg, &frame)),
            &tick,
        );
        pb.finish_and_clear();
        let accepted = trials.iter().filter(|t| t.accepted).count();
        report.json["accepted_wrong_map"] = serde_json::to_value(
            trials
                .iter()
                .filter(|t| t.accepted)
                .take(50)
                .collect::<Vec<_>>(),
        )
        .unwrap_or(Value::Null);
        self.ui.note(&format!(
            "wrong-map      n {:>5}  accepted {} ({:.2}%)",
            trials.len(),
            accepted,
            100.0 * accepted as f64 / trials.len().max(1) as f64
        ));
        // A wrong-map run has no correct answer: every acceptance is false.
        let s = Summary {
            n: trials.len(),
            accepted,
            false_accepts: accepted,
            false_accept_rate: accepted as f64 / trials.len().max(1) as f64,
            ..Summary::default()
        };
        report.summary("wrong-map", &s);
        Ok(())
    }

    /// E1: scan-to-scan SSM accuracy over `--e1-trials` simulated pairs
    /// (dumped with `--dump`).
    fn e1(&self, report: &mut Report) -> Result<(), crate::util::CliError> {
        let trials = self.e1_trials()?;
        let errs: Vec<[f64; 3]> = trials.iter().filter_map(|t| t.err).collect();
        let good: Vec<[f64; 3]> = errs
            .iter()
            .copied()
            .filter(|e| {
                (e[0].powi(2) + e[1].powi(2)).sqrt() < 0.3 && e[2].abs() < 5f64.to_radians()
            })
            .collect();
        let (m, sd) = eval::mean_sd(&good);
        self.ui.note(&format!(
            "e1             n {:>5}  matched {} ({} within 0.3 m / 5 deg)  x {:.2} ({:.2}) mm  y {:.2} ({:.2}) mm  th {:.3} ({:.3}) deg   [paper: 0.27 (10.51), -0.42 (7.99), 0.01 (0.09)]",
            trials.len(),
            errs.len(),
            good.len(),
            m[0] * 1000.0,
            sd[0] * 1000.0,
            m[1] * 1000.0,
            sd[1] * 1000.0,
            m[2].to_degrees(),
            sd[2].to_degrees()
        ));
        report.json["e1"] = json!({"trials": trials.len(), "matched": errs.len(), "correct": good.len(),
            "mean_mm_mm_deg": [m[0]*1000.0, m[1]*1000.0, m[2].to_degrees()],
            "sd_mm_mm_deg": [sd[0]*1000.0, sd[1]*1000.0, sd[2].to_degrees()],
            "paper_mean": [0.27, -0.42, 0.01], "paper_sd": [10.51, 7.99, 0.09]});
        Ok(())
    }

    /// The E1 trials, in pose order, each pair from its own random stream;
    /// with `--dump` the pairs are written to `e1-pairs.jsonl`.
    fn e1_trials(&self) -> Result<Vec<eval::E1Trial>, crate::util::CliError> {
        use rayon::prelude::*;
        let (a, db) = (self.a, &self.db);
        let pb = self.ui.progress(a.e1_trials as u64, "e1");
        let e1poses = eval::sample_poses(db, a.e1_trials, a.clearance, a.seed ^ 0xE1);
        let mut dumped: Vec<Value> = Vec::new();
        let trials: Vec<eval::E1Trial> = e1poses
            .par_iter()
            .enumerate()
            .map(|(k, p)| {
                let mut r = Rng::stream(a.seed ^ 0xE1E1, k as u64);
                let pair = eval::e1_pair(db, p, 0.010, 60, 0.4, 30f32.to_radians(), &mut r);
                let t = eval::ssm_match_pair(db, &pair);
                pb.inc(1);
                (t, a.dump.as_ref().map(|_| pair))
            })
            .collect::<Vec<_>>()
            .into_iter()
            .map(|(t, pair)| {
                if let Some(pair) = pair {
                    dumped.push(
                        json!({"k": dumped.len(), "motion": pair.motion, "inliers": pair.inliers,
                        "reference": pair.reference, "query": pair.query,
                        "ours": {"err": t.err, "time_us": t.time_us}}),
                    );
                }
                t
            })
            .collect();
        pb.finish_and_clear();
        if let Some(dir) = &a.dump {
            let text: String = dumped.iter().map(|v| format!("{v}\n")).collect();
            write_dump(dir, "e1-pairs.jsonl", &text)?;
        }
        Ok(trials)
    }

    /// E2: the SSM matching rate against rising noise and rising outliers,
    /// averaged over `--e2-trials` poses a point (Fig. 6).
    fn e2(&self, report: &mut Report) {
        use rayon::prelude::*;
        let (a, db) = (self.a, &self.db);
        let base = eval::sample_poses(db, a.e2_trials, a.clearance, a.seed ^ 0xE2);
        let curve = |noise: f32, outliers: usize, tag: u64| -> f64 {
            let rates: Vec<f64> = base
                .par_iter()
                .enumerate()
                .map(|(k, p)| {
                    let mut r = Rng::stream(a.seed ^ tag, k as u64);
                    eval::ssm_trial(db, p, noise, outliers, 0.4, 30f32.to_radians(), &mut r)
                        .matching_rate
                })
                .collect();
            rates.iter().sum::<f64>() / rates.len().max(1) as f64
        };
        let noises: Vec<f64> = (0..=10).map(|k| k as f64 * 5.0).collect();
        let ra: Vec<f64> = noises
            .iter()
            .enumerate()
            .map(|(k, &n)| curve(n as f32 / 1000.0, 72, 0x2A00 + k as u64))
            .collect();
        let ratios: Vec<f64> = (0..=10).map(|k| k as f64 * 0.1).collect();
        let n_in = db.params().sensor.beams as f64;
        let rb: Vec<f64> = ratios
            .iter()
            .enumerate()
            .map(|(k, &r)| curve(0.005, (r * n_in) as usize, 0x2B00 + k as u64))
            .collect();
        let rounded = |v: &[f64]| {
            v.iter()
                .map(|v| (v * 100.0).round() / 100.0)
                .collect::<Vec<_>>()
        };
        self.ui.note(&format!(
            "e2 (a) noise mm {:?} -> rate {:?}",
            noises,
            rounded(&ra)
        ));
        self.ui.note(&format!(
            "e2 (b) outlier ratio {:?} -> rate {:?}",
            ratios,
            rounded(&rb)
        ));
        if !a.no_figures {
            let _ = std::fs::create_dir_all(&a.out);
            let _ = figures::curve_figure(
                &noises,
                &ra,
                "E2 (a): 72 outliers, rising noise (Fig. 6a)",
                "noise sigma (mm)",
                &a.out.join("e2-noise.png"),
            );
            let _ = figures::curve_figure(
                &ratios,
                &rb,
                "E2 (b): noise 5 mm, rising outliers (Fig. 6b)",
                "outlier / inlier ratio",
                &a.out.join("e2-outliers.png"),
            );
        }
        report.json["e2"] = json!({"noise_mm": noises, "rate_vs_noise": ra, "outlier_ratio": ratios, "rate_vs_outliers": rb, "trials_per_point": a.e2_trials});
    }
}

/// The statistics of E4 run `name` beyond its summary, into `report`: the
/// E5 coarse ranks of the correct site, the long-range ratios of the
/// correct estimates, the vicinity ratios of the correct and the wrong
/// ones, and the first 50 failures.
fn e4_statistics(name: &str, trials: &[Trial], report: &mut Value) {
    let ranks: Vec<usize> = trials.iter().filter_map(|t| t.correct_rank).collect();
    let within =
        |k: usize| ranks.iter().filter(|&&r| r < k).count() as f64 / ranks.len().max(1) as f64;
    report[format!("e5_{name}")] = json!({
        "with_site_in_sight": ranks.len(),
        "rank_within": {"1": within(1), "5": within(5), "10": within(10), "20": within(20), "30": within(30)},
        "rank_histogram": (0..30).map(|k| ranks.iter().filter(|&&r| r == k).count()).collect::<Vec<_>>(),
    });
    let failures: Vec<&Trial> = trials.iter().filter(|t| !t.correct()).take(50).collect();
    let ratios = |ok: bool| -> Vec<f64> {
        let mut v: Vec<f64> = trials
            .iter()
            .filter(|t| t.est.is_some() && t.correct() == ok)
            .map(|t| t.vicinity_ratio)
            .collect();
        v.sort_by(|a, b| a.total_cmp(b));
        v
    };
    let (good, bad) = (ratios(true), ratios(false));
    let pct = |v: &[f64], q: f64| {
        v.get(((v.len() as f64 - 1.0) * q).round() as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    let mut longs: Vec<f64> = trials
        .iter()
        .filter(|t| t.correct())
        .map(|t| t.long_ratio)
        .collect();
    longs.sort_by(|a, b| a.total_cmp(b));
    report[format!("long_ratio_correct_{name}")] = json!([
        pct(&longs, 0.5),
        pct(&longs, 0.95),
        pct(&longs, 0.99),
        longs.last().copied()
    ]);
    report[format!("vicinity_{name}")] = json!({
        "correct_p01_p05_p50": [pct(&good, 0.01), pct(&good, 0.05), pct(&good, 0.5)],
        "wrong_p50_p95_p99_max": [pct(&bad, 0.5), pct(&bad, 0.95), pct(&bad, 0.99), bad.last().copied().unwrap_or(f64::NAN)],
    });
    report[format!("failures_{name}")] = serde_json::to_value(&failures).unwrap_or(Value::Null);
}

/// Writes `text` to `dir/name` (creating `dir`).
fn write_dump(dir: &std::path::Path, name: &str, text: &str) -> Result<(), crate::util::CliError> {
    std::fs::create_dir_all(dir)
        .map_err(|e| fail_err(anyhow::anyhow!("{}: {e}", dir.display())))?;
    let path = dir.join(name);
    std::fs::write(&path, text).map_err(|e| fail_err(anyhow::anyhow!("{}: {e}", path.display())))
}

/// `--dump`: the scans `run_e4` localizes for this run (the same random
/// streams), as JSON Lines with ids `scan K`, and their true robot poses.
fn dump_e4<D: AsRef<[u8]>>(
    db: &refloc::RefDb<D>,
    poses: &[refloc::Pose2],
    spec: &ScanSpec,
    seed: u64,
    dir: &std::path::Path,
    name: &str,
) -> Result<(), crate::util::CliError> {
    use mapc::tools::scanio::{scan_to_json, ScanData};
    let (grid, frame) = (db.grid(), db.frame());
    let lidar = spec.lidar();
    let (mut scans, mut truth) = (String::new(), String::new());
    for (k, p) in poses.iter().enumerate() {
        let mut rng = eval::e4_rng(seed, k);
        let sensor = p.compose(&db.params().sensor.offset);
        let s = eval::simulate(&grid, &frame, &sensor, spec, &mut rng);
        let data = match s.points {
            Some(points) => ScanData::Points {
                points,
                range_max: spec.range_max,
            },
            None => ScanData::Ranges {
                angle_min: lidar.angle_min,
                angle_increment: lidar.angle_increment,
                range_min: lidar.range_min,
                range_max: lidar.range_max,
                ranges: s.ranges,
            },
        };
        let t = [sensor.x as f64, sensor.y as f64, sensor.theta as f64];
        scans.push_str(&scan_to_json(&data, &format!("scan {k}"), Some(t)));
        scans.push('\n');
        truth.push_str(&format!("{k} 0 0 {} {} {}\n", p.x, p.y, p.theta));
    }
    write_dump(dir, &format!("{name}-scans.jsonl"), &scans)?;
    write_dump(dir, &format!("{name}-truth.txt"), &truth)
}
