//! `.refdb` reader: arbitrary bytes after a valid 16-byte header prefix, raw
//! and with the header CRC (and file length) patched; then `verify()` and
//! `localize` on whatever `RefDb::new` accepts.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    refloc_fuzz::refdb(data);
});
