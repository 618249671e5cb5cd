//! Map loader: a ROS map YAML and an image (split at `MAP_SEPARATOR`),
//! through `load_yaml` and `load_image`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    refloc_fuzz::mapfile(data);
});
