//! Puts `memory.x` where cortex-m-rt's `link.x` finds it, and rebuilds when
//! the generated inputs in `data/` change.

use std::path::PathBuf;

fn main() {
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("OUT_DIR"));
    std::fs::copy("memory.x", out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    for f in ["memory.x", "data/map.refdb", "data/scans.rs"] {
        println!("cargo:rerun-if-changed={f}");
    }
    for f in ["data/map.refdb", "data/scans.rs"] {
        if !std::path::Path::new(f).exists() {
            panic!("{f} is missing: run scripts/firmware-demo.sh (it generates data/)");
        }
    }
}
