//! ROS 2 bag reader: arbitrary bytes as an MCAP file through
//! `open_bag_bytes` and every item of `Bag::scans`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    refloc_fuzz::bag(data);
});
