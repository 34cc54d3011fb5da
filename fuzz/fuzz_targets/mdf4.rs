//! The MDF4 reader (`hils::mdf4` through `hils::measured`) on arbitrary bytes, read with
//! and without the channel map of the CANape-like fixtures: no panic, no hang, no
//! allocation beyond the file's own size class, and after a successful read the invariants
//! of `hils_fuzz::check_measured` (time finite and increasing, every channel as long as
//! the time, every value finite or empty and within its column's plausible range).
#![no_main]

use std::path::Path;
use std::sync::OnceLock;

use hils::measured::ChannelMap;
use libfuzzer_sys::fuzz_target;

fn map() -> &'static ChannelMap {
    static MAP: OnceLock<ChannelMap> = OnceLock::new();
    MAP.get_or_init(|| {
        ChannelMap::parse(
            Path::new("canape.map.toml"),
            include_str!("../../tools/tests/data/mdf4/canape_sorted.map.toml"),
        )
        .expect("the fixture's map")
    })
}

fuzz_target!(|data: &[u8]| {
    // Every input is taken as an MDF4 file (the reader picks MDF4 by the identification).
    let mut bytes = b"MDF     4.10    ".to_vec();
    bytes.extend_from_slice(data);
    for m in [None, Some(map())] {
        if let Ok(read) = hils::measured::parse_bytes_with(Path::new("fuzz.mf4"), &bytes, m) {
            hils_fuzz::check_measured(&read);
        }
    }
});
