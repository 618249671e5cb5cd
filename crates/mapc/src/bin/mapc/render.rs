//! `mapc render` (being written).
use crate::util::{CliResult, Ui};

#[derive(clap::Args, Debug)]
pub struct Args {}

pub fn run(_a: Args, _ui: &Ui) -> CliResult {
    Err(crate::util::fail_err(anyhow::anyhow!("not yet")))
}
