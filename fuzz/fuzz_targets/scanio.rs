//! Scan readers: arbitrary bytes through `read_scans` in every format, with
//! default and small limits.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    refloc_fuzz::scanio(data);
});
