//! `mapc`: the refloc map compiler and its companions.
//!
//! Exit codes: 0 success; 1 the command ran but its check failed (verify,
//! eval --check, a localize line that failed); 2 bad usage or bad input
//! (unreadable map, malformed options, unreadable database).

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod build;
mod demo;
mod eval;
mod inspect;
mod localize;
mod render;
mod stages;
mod synth;
mod util;

/// refloc map compiler: occupancy grid to reference database (.refdb), and
/// tools to inspect, verify, evaluate and localize against it.
#[derive(Parser, Debug)]
#[command(name = "mapc", version, about, propagate_version = true)]
struct Cli {
    /// Worker threads, 1 to 256 (default: all cores). Output does not depend on it.
    #[arg(long, global = true, value_name = "N")]
    threads: Option<usize>,
    /// Skip the CRC check of the database that info, localize, eval and
    /// diff make when they open it (the structure is always checked).
    #[arg(long, global = true)]
    no_verify: bool,
    /// No progress bars or summaries on stderr.
    #[arg(long, short, global = true)]
    quiet: bool,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Compile a ROS map (YAML, or PGM/PNG image) into a .refdb.
    Build(build::Args),
    /// Print what a .refdb holds (header, sections, parameters, manifest).
    Info(inspect::InfoArgs),
    /// Check a .refdb's structure and checksums (exit 0 or 1).
    Verify(inspect::VerifyArgs),
    /// Compare two .refdb files (sites, parameters, inputs, section contents; exit 1 when they differ).
    Diff(inspect::DiffArgs),
    /// Localize scans (JSON Lines, CARMEN log or ROS 2 bag) against a .refdb.
    #[command(after_long_help = localize::FORMATS)]
    Localize(localize::Args),
    /// Evaluate localization on simulated scans (the paper's experiments).
    Eval(eval::Args),
    /// Compile the shipped demo map, localize simulated scans, write figures.
    Demo(demo::Args),
    /// Draw a map with its GVD, graph and sites (PNG).
    Render(render::Args),
    /// Generate a synthetic map (office, warehouse, cave) as PGM + YAML.
    Synth(synth::Args),
    /// Time the distance transform and GVD stages alone and write them as .npy (for bench/peers).
    #[command(hide = true)]
    Stages(stages::Args),
}

/// The most worker threads `--threads` accepts: far above any machine's
/// useful count, and a bound on what one option can make the process spawn.
const MAX_THREADS: usize = 256;

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Some(n) = cli.threads {
        if !(1..=MAX_THREADS).contains(&n) {
            eprintln!("error: --threads must be between 1 and {MAX_THREADS}, not {n}");
            return ExitCode::from(2);
        }
        if let Err(e) = rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
        {
            eprintln!("error: cannot set up {n} threads: {e}");
            return ExitCode::from(2);
        }
    }
    util::set_verify_crcs(!cli.no_verify);
    let ui = util::Ui::new(cli.quiet);
    let r = match cli.cmd {
        Cmd::Build(a) => build::run(a, &ui),
        Cmd::Info(a) => inspect::info(a),
        Cmd::Verify(a) => inspect::verify(a),
        Cmd::Diff(a) => inspect::diff(a),
        Cmd::Localize(a) => localize::run(a, &ui),
        Cmd::Eval(a) => eval::run(a, &ui),
        Cmd::Demo(a) => demo::run(a, &ui),
        Cmd::Render(a) => render::run(a, &ui),
        Cmd::Synth(a) => synth::run(a, &ui),
        Cmd::Stages(a) => stages::run(a, &ui),
    };
    match r {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {:#}", e.error);
            ExitCode::from(e.code)
        }
    }
}
