//! `mapc synth`: synthetic maps the project owns.

use std::path::PathBuf;
use std::process::ExitCode;

use mapc::tools::synth::{self, SynthKind, SynthOptions};

use crate::util::outln;
use crate::util::{fail_err, input_err, parse_triple, CliResult, Ui};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Kind of map.
    #[arg(long, value_enum, default_value_t = SynthKind::Office)]
    pub kind: SynthKind,
    /// Width (cells, at least 16).
    #[arg(long, default_value_t = 1000)]
    pub width: u32,
    /// Height (cells, at least 16).
    #[arg(long, default_value_t = 1000)]
    pub height: u32,
    /// Metres per cell.
    #[arg(long, default_value_t = 0.05, value_name = "M")]
    pub resolution: f64,
    /// Seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Map origin "x,y,yaw" (m, m, rad) written to the YAML.
    #[arg(long, value_name = "X,Y,YAW", value_parser = parse_triple, allow_hyphen_values = true)]
    pub origin: Option<[f64; 3]>,
    /// Output directory.
    #[arg(
        short,
        long,
        default_value = "build-artifacts/synth",
        value_name = "DIR"
    )]
    pub out: PathBuf,
    /// Map name (file stem) [default: <kind>-<width>x<height>-s<seed>].
    #[arg(long)]
    pub name: Option<String>,
}

/// The smallest side `mapc synth` makes (cells): the smallest every
/// generator fills with a map that `mapc build` compiles (measured: 16 x 16
/// builds for office, warehouse and cave at seeds 1-3; 8 x 8 has no site).
const MIN_SIDE: u32 = 16;

pub fn run(a: Args, ui: &Ui) -> CliResult {
    let kind = a.kind;
    if !(a.resolution.is_finite() && a.resolution > 0.0) {
        return Err(input_err(anyhow::anyhow!(
            "--resolution must be a positive number of metres per cell"
        )));
    }
    if a.width < MIN_SIDE || a.height < MIN_SIDE {
        return Err(input_err(anyhow::anyhow!(
            "--width and --height must be at least {MIN_SIDE} cells (got {} x {}): smaller maps have no free space a robot fits in, and `mapc build` would refuse them",
            a.width,
            a.height
        )));
    }
    if a.width as u64 * a.height as u64 > (1u64 << 31) {
        return Err(input_err(anyhow::anyhow!(
            "{} x {} cells is more than 2^31 cells",
            a.width,
            a.height
        )));
    }
    let mut opts = SynthOptions::new(kind, a.width, a.height);
    opts.resolution = a.resolution;
    opts.seed = a.seed;
    let t = std::time::Instant::now();
    let map = synth::generate(&opts);
    let name = a
        .name
        .clone()
        .unwrap_or_else(|| format!("{}-{}x{}-s{}", kind.as_str(), a.width, a.height, a.seed));
    for ext in ["pgm", "yaml"] {
        let f = a.out.join(format!("{name}.{ext}"));
        mapc::compiler::writer::check_output_path(&f, &[])
            .map_err(|e| input_err(anyhow::anyhow!("{}: {e}", f.display())))?;
    }
    let (yaml, _) = synth::write_ros_map(&a.out, &name, &map, a.origin.unwrap_or([0.0; 3]))
        .map_err(|e| fail_err(anyhow::anyhow!("{}: {e}", a.out.display())))?;
    ui.note(&format!(
        "{} ({} x {} cells, {:.2} s)",
        yaml.display(),
        map.width,
        map.height,
        t.elapsed().as_secs_f64()
    ));
    outln!("{}", yaml.display());
    Ok(ExitCode::SUCCESS)
}
