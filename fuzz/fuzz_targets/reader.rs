//! The run-log and friction-test reader on arbitrary bytes: no panic, no hang, and after a
//! successful read the invariants of `hils_fuzz::check_measured`.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    if let Ok(m) = hils::measured::parse_bytes(Path::new("fuzz.csv"), data) {
        hils_fuzz::check_measured(&m);
    }
});
