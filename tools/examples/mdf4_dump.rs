//! Prints every channel of MDF4 files as the project's reader reads them, one JSON line per
//! channel group (`{"file", "group", "t", "channels": {name: values}}` or `{"error"}`), for
//! checks against asammdf (`python3 scripts/mdf4_asammdf.py vlsd DUMP`). Built only with
//! `--features mdf4-dump`, so `cargo test` does not build it.
use hils::mdf4::{Mdf4, blocks::FileSource, data::Values};
fn main() {
    for path in std::env::args().skip(1) {
        let opened = std::fs::File::open(&path).and_then(FileSource::new);
        let Ok(f) = opened else {
            println!(
                "{}",
                serde_json::json!({"file": path, "error": "cannot open"})
            );
            continue;
        };
        let m = match Mdf4::open(&f) {
            Ok(m) => m,
            Err(e) => {
                println!("{}", serde_json::json!({"file": path, "error": e}));
                continue;
            }
        };
        for (g, grp) in m.groups.iter().enumerate() {
            if grp.is_vlsd() {
                continue;
            }
            let wanted: Vec<usize> = (0..grp.channels.len())
                .filter(|&i| !grp.channels[i].is_master())
                .collect();
            let line = match m.read_group(g, &wanted) {
                Ok((t, vals)) => {
                    let mut ch = serde_json::Map::new();
                    for (&i, v) in wanted.iter().zip(vals) {
                        let j = match v {
                            Values::Num(x) => serde_json::json!(x),
                            Values::Text(t) => serde_json::json!(t.iter().collect::<Vec<_>>()),
                        };
                        ch.insert(grp.channels[i].name.clone(), j);
                    }
                    serde_json::json!({"file": path, "group": g, "t": t, "channels": ch})
                }
                Err(e) => {
                    serde_json::json!({"file": path, "group": g, "error": format!("{}: {}", e.channel, e.message)})
                }
            };
            println!("{line}");
        }
    }
}
