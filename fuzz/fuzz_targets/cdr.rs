//! CDR decoder: arbitrary bytes as one `sensor_msgs/msg/LaserScan`
//! message through `decode_laser_scan`, and the round trip of what decodes.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    refloc_fuzz::cdr(data);
});
