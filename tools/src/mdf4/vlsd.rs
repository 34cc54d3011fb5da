//! Variable-length signal data (VLSD) of text channels (ASAM MDF 4.1/4.2, `cn_type` 1):
//! the record holds the 64-bit offset of the sample's entry (a u32 length, then the bytes)
//! in the channel's signal data. That is an SD block, a DL list (or HL header) of SD
//! blocks, a DZ block holding one ([`SignalData`]), or, in MDF 4.2, a VLSD channel group
//! of the same unsorted data group whose records carry the entries in order
//! ([`VlsdRecords`]: the offset counts the entries' bytes, length prefixes included,
//! without record ids).
//!
//! Signal data is read by offset through a window of at most 1 MiB (or one DZ block), so
//! a channel's texts are never read whole; every offset and length is checked against the
//! signal data's size.

use super::blocks::Blocks;
use super::data::{Piece, inflate, pieces};
use crate::measured::TextColumn;

/// Bytes of signal data read from an SD block at a time.
const WINDOW_BYTES: u64 = 1 << 20;

/// Longest text entry read (a command or state text is a few bytes): 1 MiB.
const MAX_TEXT_BYTES: u64 = 1 << 20;

/// A channel's signal data read by offset (SD, DZ of SD, DL/HL lists of them).
pub(super) struct SignalData<'b, 'a> {
    blocks: &'b Blocks<'a>,
    pieces: Vec<Piece>,
    /// Offset in the signal data where each piece starts.
    starts: Vec<u64>,
    total: u64,
    /// The bytes read last and where they start.
    window_start: u64,
    window: Vec<u8>,
}

impl<'b, 'a> SignalData<'b, 'a> {
    /// The signal data at `addr` (0: none), its blocks' headers checked, no data read.
    pub(super) fn new(blocks: &'b Blocks<'a>, addr: u64) -> Result<Self, String> {
        let pieces = pieces(blocks, addr, &[b"SD"])?;
        let mut starts = Vec::with_capacity(pieces.len());
        let mut total = 0u64;
        for p in &pieces {
            starts.push(total);
            total = total
                .checked_add(p.stream_len())
                .ok_or("signal data longer than 2^64 bytes: a damaged list")?;
        }
        Ok(Self {
            blocks,
            pieces,
            starts,
            total,
            window_start: 0,
            window: Vec::new(),
        })
    }

    /// Reads the window that holds `at` (< the signal data's size).
    fn load(&mut self, at: u64) -> Result<(), String> {
        let i = self.starts.partition_point(|&s| s <= at).saturating_sub(1);
        let p = &self.pieces[i];
        match *p {
            Piece::Raw { addr, len } => {
                let from = at - self.starts[i];
                let n = (len - from).min(WINDOW_BYTES);
                self.window = self.blocks.bytes(addr + from, n, "signal data")?;
                self.window_start = at;
            }
            Piece::Zipped { .. } => {
                self.window = inflate(self.blocks, p)?;
                self.window_start = self.starts[i];
            }
        }
        let end = self.window_start + self.window.len() as u64;
        if !(self.window_start..end).contains(&at) {
            return Err(format!("signal data at offset {at}: no block holds it"));
        }
        Ok(())
    }

    /// `n` bytes from offset `at` (the caller checked `at + n` against the size).
    fn read(&mut self, at: u64, n: u64) -> Result<Vec<u8>, String> {
        let mut out = Vec::with_capacity(n as usize);
        let mut pos = at;
        while (out.len() as u64) < n {
            let end = self.window_start + self.window.len() as u64;
            if !(self.window_start..end).contains(&pos) {
                self.load(pos)?;
            }
            let from = (pos - self.window_start) as usize;
            let take = ((n - out.len() as u64) as usize).min(self.window.len() - from);
            out.extend_from_slice(&self.window[from..from + take]);
            pos += take as u64;
        }
        Ok(out)
    }

    /// The bytes of the entry at `offset` (a u32 length, then the bytes), checked.
    pub(super) fn entry(&mut self, offset: u64) -> Result<Vec<u8>, String> {
        let total = self.total;
        if offset.checked_add(4).is_none_or(|end| end > total) {
            return Err(format!(
                "its text's offset {offset} lies outside the channel's {total} bytes of signal \
                 data: a damaged file"
            ));
        }
        let len = u32::from_le_bytes(self.read(offset, 4)?.try_into().unwrap_or_default()) as u64;
        if (offset + 4).saturating_add(len) > total {
            return Err(format!(
                "its text at offset {offset} ({len} bytes) runs past the end of the channel's \
                 {total} bytes of signal data: a damaged file"
            ));
        }
        if len > MAX_TEXT_BYTES {
            return Err(format!(
                "a text of {len} bytes at offset {offset}: not a command or state text"
            ));
        }
        self.read(offset + 4, len)
    }
}

/// The entries of a VLSD channel group (MDF 4.2), collected from the records of its
/// unsorted data group, each text once.
pub(super) struct VlsdRecords {
    /// The VLSD group's record id.
    pub(super) record_id: u64,
    data_type: u8,
    /// Offset of the next entry.
    next: u64,
    /// Offset of every entry and its text's code in `texts`.
    offsets: Vec<u64>,
    codes: Vec<u32>,
    pub(super) texts: TextColumn,
    /// Offsets of the entries that do not decode, with why (increasing).
    damaged: Vec<(u64, &'static str)>,
    /// Entries the VLSD group says it has (its cycle count).
    pub(super) expected: u64,
}

impl VlsdRecords {
    pub(super) fn new(record_id: u64, data_type: u8, expected: u64) -> Self {
        Self {
            record_id,
            data_type,
            next: 0,
            offsets: Vec::new(),
            codes: Vec::new(),
            texts: TextColumn::default(),
            damaged: Vec::new(),
            expected,
        }
    }

    /// Adds the entry of one VLSD record (its bytes after the length). An entry that does
    /// not decode is kept as damaged: a record that refers to it is an error.
    pub(super) fn push(&mut self, value: &[u8]) {
        let text = entry_text(self.data_type, value).unwrap_or_else(|why| {
            self.damaged.push((self.next, why));
            String::new()
        });
        self.texts.push(&text);
        self.offsets.push(self.next);
        self.codes.push(self.texts.codes.pop().unwrap_or_default());
        self.next += 4 + value.len() as u64;
    }

    /// The text of the entry at `offset` (None: no entry starts there; Some(Err): the
    /// entry does not decode, and why).
    pub(super) fn text(&self, offset: u64) -> Option<Result<&str, &'static str>> {
        let i = self.offsets.binary_search(&offset).ok()?;
        if let Ok(d) = self.damaged.binary_search_by_key(&offset, |&(at, _)| at) {
            return Some(Err(self.damaged[d].1));
        }
        Some(Ok(&self.texts.values[self.codes[i] as usize]))
    }

    /// Entries collected.
    pub(super) fn count(&self) -> u64 {
        self.offsets.len() as u64
    }

    /// Bytes of entries collected.
    pub(super) fn len_bytes(&self) -> u64 {
        self.next
    }
}

/// The text of a variable-length string entry of data type 6-9, decoded strictly: an
/// entry that is not valid UTF-8, or UTF-16 of an odd length or with an unpaired
/// surrogate, is a damaged value (Err: why), never a text with replacement characters.
pub(super) fn entry_text(data_type: u8, b: &[u8]) -> Result<String, &'static str> {
    match data_type {
        7 => std::str::from_utf8(up_to_nul(b))
            .map(str::to_owned)
            .map_err(|_| "its text is not valid UTF-8"),
        8 | 9 if b.len() % 2 != 0 => Err("its UTF-16 text has an odd number of bytes"),
        8 | 9 => String::from_utf16(&utf16_units(data_type, b))
            .map_err(|_| "its UTF-16 text is not valid UTF-16"),
        _ => Ok(text_of(data_type, b)),
    }
}

/// The text of a string value of MDF4 data type 6-9 (Latin-1, UTF-8, UTF-16 LE/BE), up to
/// its first NUL (the padding of a fixed-length string).
pub(super) fn text_of(data_type: u8, b: &[u8]) -> String {
    match data_type {
        6 => up_to_nul(b).iter().map(|&c| c as char).collect(),
        7 => String::from_utf8_lossy(up_to_nul(b)).into_owned(),
        _ => String::from_utf16_lossy(&utf16_units(data_type, b)),
    }
}

/// The bytes before the first NUL.
fn up_to_nul(b: &[u8]) -> &[u8] {
    &b[..b.iter().position(|&c| c == 0).unwrap_or(b.len())]
}

/// The UTF-16 code units (data type 8: little-endian, 9: big-endian) before the first NUL
/// unit; an odd last byte is not read.
fn utf16_units(data_type: u8, b: &[u8]) -> Vec<u16> {
    b.chunks_exact(2)
        .map(|c| match data_type {
            8 => u16::from_le_bytes([c[0], c[1]]),
            _ => u16::from_be_bytes([c[0], c[1]]),
        })
        .take_while(|&u| u != 0)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::Mdf4;
    use super::super::blocks::Memory;
    use super::super::data::{ChannelError, Values};

    /// A hand-built MDF 4.2 file: blocks appended at 8-byte boundaries.
    struct File(Vec<u8>);

    impl File {
        /// The identification block and an HD block (at 64) without data groups.
        fn new() -> Self {
            let mut f = File(b"MDF     4.20    hils    ".to_vec());
            f.0.resize(64, 0);
            f.0[28..30].copy_from_slice(&420u16.to_le_bytes());
            f.add(b"HD", &[0; 6], &[0; 32]);
            f
        }

        fn add(&mut self, id: &[u8; 2], links: &[u64], data: &[u8]) -> u64 {
            while self.0.len() % 8 != 0 {
                self.0.push(0);
            }
            let addr = self.0.len() as u64;
            let length = 24 + 8 * links.len() + data.len();
            self.0
                .extend_from_slice(&[b'#', b'#', id[0], id[1], 0, 0, 0, 0]);
            self.0.extend_from_slice(&(length as u64).to_le_bytes());
            self.0
                .extend_from_slice(&(links.len() as u64).to_le_bytes());
            for l in links {
                self.0.extend_from_slice(&l.to_le_bytes());
            }
            self.0.extend_from_slice(data);
            addr
        }

        fn set_link(&mut self, block: u64, i: usize, value: u64) {
            let at = block as usize + 24 + 8 * i;
            self.0[at..at + 8].copy_from_slice(&value.to_le_bytes());
        }

        /// A channel (name, type, data type, byte offset, 64 bits, its `cn_data`).
        fn channel(&mut self, name: &str, cn_type: u8, data_type: u8, at: u32, data: u64) -> u64 {
            let tx = self.add(b"TX", &[], format!("{name}\0").as_bytes());
            let mut d = vec![cn_type, u8::from(cn_type == 2), data_type, 0];
            d.extend_from_slice(&at.to_le_bytes());
            d.extend_from_slice(&64u32.to_le_bytes());
            d.resize(72, 0);
            self.add(b"CN", &[0, 0, tx, 0, 0, data, 0, 0], &d)
        }

        fn group(&mut self, record_id: u64, cycles: u64, flags: u16, bytes: u32, cn: u64) -> u64 {
            let mut d = Vec::new();
            d.extend_from_slice(&record_id.to_le_bytes());
            d.extend_from_slice(&cycles.to_le_bytes());
            d.extend_from_slice(&flags.to_le_bytes());
            d.extend_from_slice(&[0; 6]);
            d.extend_from_slice(&bytes.to_le_bytes());
            d.extend_from_slice(&0u32.to_le_bytes());
            self.add(b"CG", &[0, cn, 0, 0, 0, 0], &d)
        }

        /// One data group of `cg` with records `data` (record ids of `id_bytes`).
        fn data_group(&mut self, cg: u64, id_bytes: u8, data: &[u8]) {
            let dt = self.add(b"DT", &[], data);
            let dg = self.add(b"DG", &[0, cg, dt, 0], &[id_bytes, 0, 0, 0, 0, 0, 0, 0]);
            self.set_link(64, 0, dg);
        }

        /// The texts of channel `cmd` (group 1, channel 2), or the error.
        fn cmd(&self) -> Result<Vec<String>, ChannelError> {
            let src = Memory(&self.0);
            let mdf = Mdf4::open(&src).expect("the file opens");
            let (_, mut v) = mdf.read_group(0, &[1])?;
            match v.remove(0) {
                Values::Text(t) => Ok(t.iter().map(str::to_string).collect()),
                Values::Num(_) => panic!("numbers"),
            }
        }
    }

    /// `e` is about channel `cmd`, record `record` (1-based), and says `phrase`.
    fn assert_names_record(e: &ChannelError, record: u32, phrase: &str) {
        assert_eq!(e.channel, "cmd");
        let at = format!("record {record} of its channel group");
        assert!(e.message.contains(&at), "{}", e.message);
        assert!(e.message.contains(phrase), "{}", e.message);
    }

    /// Length-prefixed entries.
    fn entries(texts: &[&[u8]]) -> Vec<u8> {
        let mut out = Vec::new();
        for t in texts {
            out.extend_from_slice(&(t.len() as u32).to_le_bytes());
            out.extend_from_slice(t);
        }
        out
    }

    /// Records of a time (s) and an offset, each after `id` when given.
    fn records(offsets: &[u64], id: Option<u8>) -> Vec<u8> {
        let mut out = Vec::new();
        for (i, o) in offsets.iter().enumerate() {
            out.extend(id);
            out.extend_from_slice(&(i as f64 * 0.01).to_le_bytes());
            out.extend_from_slice(&o.to_le_bytes());
        }
        out
    }

    /// A sorted group whose text channel's `cn_data` is the signal data at `sd`.
    fn sorted_file(sd: impl FnOnce(&mut File) -> u64, data_type: u8, offsets: &[u64]) -> File {
        let mut f = File::new();
        let sd = sd(&mut f);
        let cmd = f.channel("cmd", 1, data_type, 8, sd);
        let t = f.channel("t", 2, 4, 0, 0);
        f.set_link(t, 0, cmd);
        let cg = f.group(0, offsets.len() as u64, 0, 16, t);
        f.data_group(cg, 0, &records(offsets, None));
        f
    }

    #[test]
    fn texts_are_read_by_their_offsets_in_signal_data() {
        let sd = |f: &mut File| f.add(b"SD", &[], &entries(&[b"REL", b"EB\0\0"]));
        let f = sorted_file(sd, 7, &[0, 7, 0, 7]);
        assert_eq!(f.cmd().unwrap(), ["REL", "EB", "REL", "EB"]);
        // Latin-1 and UTF-16 of either byte order.
        let sd = |f: &mut File| f.add(b"SD", &[], &entries(&[b"L\xf6sen"]));
        assert_eq!(sorted_file(sd, 6, &[0]).cmd().unwrap(), ["Lösen"]);
        let sd = |f: &mut File| f.add(b"SD", &[], &entries(&[b"E\0B\0\0\0"]));
        assert_eq!(sorted_file(sd, 8, &[0]).cmd().unwrap(), ["EB"]);
        let sd = |f: &mut File| f.add(b"SD", &[], &entries(&[b"\0E\0B"]));
        assert_eq!(sorted_file(sd, 9, &[0]).cmd().unwrap(), ["EB"]);
    }

    /// A DL list of SD blocks is one stream of signal data, even where an entry is split
    /// between two blocks.
    #[test]
    fn a_list_of_signal_data_blocks_is_one_stream() {
        let all = entries(&[b"REL", b"SERVICE_3", b"EB"]);
        let sd = |f: &mut File| {
            let a = f.add(b"SD", &[], &all[..9]);
            let b = f.add(b"SD", &[], &all[9..]);
            let dl = f.add(b"DL", &[0, a, b], &[0; 8]);
            f.add(b"HL", &[dl], &[0; 8])
        };
        let f = sorted_file(sd, 7, &[20, 7, 0]);
        assert_eq!(f.cmd().unwrap(), ["EB", "SERVICE_3", "REL"]);
    }

    /// An offset or a length outside the signal data: an error naming the channel and
    /// the record, never a panic.
    #[test]
    fn a_bad_offset_is_an_error_naming_the_channel_and_record() {
        let sd = |f: &mut File| f.add(b"SD", &[], &entries(&[b"REL"]));
        for bad in [8, 5, 1 << 40, u64::MAX] {
            let e = sorted_file(sd, 7, &[0, bad]).cmd().unwrap_err();
            assert_names_record(&e, 2, &format!("offset {bad}"));
        }
        // A length running past the end; no signal data at all.
        let long = |f: &mut File| f.add(b"SD", &[], &[200, 0, 0, 0, b'R']);
        let e = sorted_file(long, 7, &[0]).cmd().unwrap_err();
        assert!(
            e.message.contains("(200 bytes) runs past the end"),
            "{}",
            e.message
        );
        let e = sorted_file(|_| 0, 7, &[0]).cmd().unwrap_err();
        assert!(
            e.message.contains("outside the channel's 0 bytes"),
            "{}",
            e.message
        );
    }

    /// MDF 4.2: `cn_data` points to a VLSD channel group whose records, in the same
    /// unsorted data group, carry the entries; the offset counts their bytes.
    fn vlsd_group_file(offsets: &[u64]) -> File {
        vlsd_group_file_saying(offsets, 3)
    }

    /// The same, the VLSD group saying it has `said_entries` entries (it holds 3).
    fn vlsd_group_file_saying(offsets: &[u64], said_entries: u64) -> File {
        let mut f = File::new();
        let vlsd_cg = f.group(2, said_entries, 1, 0, 0);
        let cmd = f.channel("cmd", 1, 7, 8, vlsd_cg);
        let t = f.channel("t", 2, 4, 0, 0);
        f.set_link(t, 0, cmd);
        let cg = f.group(1, offsets.len() as u64, 0, 16, t);
        f.set_link(cg, 0, vlsd_cg);
        let recs = records(offsets, Some(1));
        let mut data = Vec::new();
        for (i, text) in [&b"REL"[..], b"EB", b"REL"].iter().enumerate() {
            data.push(2);
            data.extend_from_slice(&entries(&[text]));
            data.extend_from_slice(&recs[17 * i..17 * (i + 1)]);
        }
        f.data_group(cg, 1, &data);
        f
    }

    #[test]
    fn texts_are_read_from_a_vlsd_channel_group() {
        let f = vlsd_group_file(&[0, 7, 13]);
        assert_eq!(f.cmd().unwrap(), ["REL", "EB", "REL"]);
        let e = vlsd_group_file(&[0, 7, 12]).cmd().unwrap_err();
        assert_names_record(&e, 3, "offset 12 is the start of no entry");
    }

    /// A text that does not decode is a damaged value named by channel and record, never
    /// a text with replacement characters (`R\u{fffd}L`) that a command might judge.
    #[test]
    fn a_text_that_does_not_decode_is_an_error_naming_its_record() {
        let utf8 = |f: &mut File| f.add(b"SD", &[], &entries(&[b"REL", b"R\xffL"]));
        let e = sorted_file(utf8, 7, &[0, 7]).cmd().unwrap_err();
        assert_names_record(&e, 2, "not valid UTF-8");
        let odd = |f: &mut File| f.add(b"SD", &[], &entries(&[b"R\0E\0L\0", b"EB\0"]));
        let e = sorted_file(odd, 8, &[0, 10]).cmd().unwrap_err();
        assert_names_record(&e, 2, "odd number of bytes");
        assert_eq!(
            sorted_file(|f| f.add(b"SD", &[], &entries(&[b"R\0E\0L\0"])), 8, &[0])
                .cmd()
                .unwrap(),
            ["REL"]
        );
    }

    /// A VLSD channel group holding fewer entries than it says is a damaged file, as a
    /// data group with fewer records than its group says is.
    #[test]
    fn a_vlsd_group_short_of_its_entries_is_an_error() {
        let e = vlsd_group_file_saying(&[0, 7, 13], 8).cmd().unwrap_err();
        assert_eq!(e.channel, "cmd");
        assert!(
            e.message.contains("holds 3 entries, the group says 8"),
            "{}",
            e.message
        );
    }
}
