//! `hils decode`'s telemetry decoder on arbitrary text: no panic; every run it decodes
//! writes a CSV that the run-log reader accepts, with the invariants of a read log.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let Ok(runs) = hils::decode::parse_runs(text.lines()) else {
        return;
    };
    for run in &runs {
        if run.records.is_empty() {
            continue;
        }
        let mut csv = Vec::new();
        // A run with an implausible value is refused (naming step and column); what is
        // written must pass the reader.
        if run.write_csv(&mut csv, "fuzz").is_err() {
            continue;
        }
        let read = hils::measured::parse_bytes(Path::new("decoded.csv"), &csv);
        match read {
            Ok(hils::measured::Measured::Run(r)) => hils_fuzz::check_run_log(&r),
            Ok(_) => panic!("decoded run read as a friction test"),
            Err(e) => panic!(
                "the reader rejects decode's output: {e}\n{}",
                String::from_utf8_lossy(&csv)
            ),
        }
    }
});
