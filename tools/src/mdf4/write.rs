//! The MDF 4.10 writer: one data group, one channel group, sorted, the time as master
//! channel; numbers as 64-bit floats (NaN: not measured), texts as 32-bit codes with a
//! value-to-text conversion (each distinct text once); every channel with its unit and
//! comment; the metadata as `<common_properties>` of the header's comment (what asammdf
//! and the measurement tools show as the file's properties).
//!
//! The blocks are laid out in order (identification, header, file history, texts,
//! conversions, channels, group) with the record data last, streamed record by record.

use std::io::Write;

/// A column to write.
pub struct Column<'a> {
    pub name: &'a str,
    pub unit: &'a str,
    pub comment: &'a str,
    pub values: ColumnValues,
}

/// A column's values.
pub enum ColumnValues {
    Num(Vec<f64>),
    /// The distinct texts and each record's index into them.
    Text {
        texts: Vec<String>,
        codes: Vec<u32>,
    },
}

impl ColumnValues {
    fn len(&self) -> usize {
        match self {
            ColumnValues::Num(v) => v.len(),
            ColumnValues::Text { codes, .. } => codes.len(),
        }
    }
    fn bytes(&self) -> u32 {
        match self {
            ColumnValues::Num(_) => 8,
            ColumnValues::Text { .. } => 4,
        }
    }
}

/// The blocks before the record data, with their addresses.
struct Layout {
    buf: Vec<u8>,
}

impl Layout {
    fn addr(&self) -> u64 {
        self.buf.len() as u64
    }

    /// Appends a block (`id` = `b"HD"`); returns its address. The data is padded to 8 bytes.
    fn block(&mut self, id: &[u8; 2], links: &[u64], data: &[u8]) -> u64 {
        let at = self.addr();
        let pad = (8 - data.len() % 8) % 8;
        let length = 24 + 8 * links.len() + data.len() + pad;
        self.buf.extend_from_slice(b"##");
        self.buf.extend_from_slice(id);
        self.buf.extend_from_slice(&[0; 4]);
        self.buf.extend_from_slice(&(length as u64).to_le_bytes());
        self.buf
            .extend_from_slice(&(links.len() as u64).to_le_bytes());
        for l in links {
            self.buf.extend_from_slice(&l.to_le_bytes());
        }
        self.buf.extend_from_slice(data);
        self.buf.extend(std::iter::repeat_n(0u8, pad));
        at
    }

    /// A TX block of `text` (0 for an empty text).
    fn tx(&mut self, text: &str) -> u64 {
        if text.is_empty() {
            return 0;
        }
        let mut data = text.as_bytes().to_vec();
        data.push(0);
        self.block(b"TX", &[], &data)
    }

    /// An MD block of `xml`.
    fn md(&mut self, xml: &str) -> u64 {
        let mut data = xml.as_bytes().to_vec();
        data.push(0);
        self.block(b"MD", &[], &data)
    }
}

/// XML text with `&`, `<`, `>`, `"` escaped.
fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The header comment: a text and the metadata as properties.
fn header_xml(comment: &str, metadata: &[(&str, String)]) -> String {
    let mut x = format!("<HDcomment><TX>{}</TX><common_properties>", escape(comment));
    for (k, v) in metadata {
        x += &format!("<e name=\"{}\">{}</e>", escape(k), escape(v));
    }
    x + "</common_properties></HDcomment>"
}

/// The CN block's data: type, sync, data type, bit offset, byte offset, bit count, flags.
fn cn_data(cn_type: u8, sync: u8, data_type: u8, byte_offset: u32, bits: u32) -> Vec<u8> {
    let mut d = vec![cn_type, sync, data_type, 0];
    d.extend_from_slice(&byte_offset.to_le_bytes());
    d.extend_from_slice(&bits.to_le_bytes());
    d.extend_from_slice(&0u32.to_le_bytes()); // flags
    d.extend_from_slice(&0u32.to_le_bytes()); // invalidation bit
    d.extend_from_slice(&[0, 0, 0, 0]); // precision, reserved, attachments
    d.extend(std::iter::repeat_n(0u8, 6 * 8)); // ranges and limits
    d
}

/// A value-to-text conversion (CC type 7) of `texts` (code i -> texts[i]).
fn vtab(l: &mut Layout, texts: &[String]) -> u64 {
    let mut refs: Vec<u64> = texts
        .iter()
        .map(|t| {
            let mut data = t.as_bytes().to_vec();
            data.push(0);
            l.block(b"TX", &[], &data)
        })
        .collect();
    refs.push(0); // default: no text
    let mut links = vec![0u64; 4];
    links.extend_from_slice(&refs);
    let n = texts.len() as u16;
    let mut d = vec![7u8, 0];
    d.extend_from_slice(&0u16.to_le_bytes());
    d.extend_from_slice(&(n + 1).to_le_bytes());
    d.extend_from_slice(&n.to_le_bytes());
    d.extend_from_slice(&0f64.to_le_bytes());
    d.extend_from_slice(&0f64.to_le_bytes());
    for i in 0..n {
        d.extend_from_slice(&(i as f64).to_le_bytes());
    }
    l.block(b"CC", &links, &d)
}

/// Writes an MDF 4.10 file: `time_s` as master, `columns` in order, `metadata` as the
/// header's properties, `comment` as its text. Texts beyond 65,535 distinct values per
/// column are an error.
pub fn write<W: Write>(
    mut out: W,
    comment: &str,
    metadata: &[(&str, String)],
    time_s: &[f64],
    columns: &[Column],
) -> std::io::Result<()> {
    let rows = time_s.len();
    for c in columns {
        if c.values.len() != rows {
            return Err(std::io::Error::other(format!(
                "column `{}`: {} values for {rows} times",
                c.name,
                c.values.len()
            )));
        }
        if let ColumnValues::Text { texts, .. } = &c.values {
            if texts.len() >= u16::MAX as usize {
                return Err(std::io::Error::other(format!(
                    "column `{}`: {} distinct texts (at most 65,534)",
                    c.name,
                    texts.len()
                )));
            }
        }
    }
    let mut l = Layout {
        buf: Vec::with_capacity(4096),
    };
    l.buf.extend_from_slice(b"MDF     4.10    hils    ");
    l.buf.extend_from_slice(&[0; 4]);
    l.buf.extend_from_slice(&410u16.to_le_bytes());
    l.buf.extend(std::iter::repeat_n(0u8, 64 - l.buf.len()));
    // HD at 64; its links are patched once the blocks they point to exist.
    let hd = l.block(b"HD", &[0; 6], &[0u8; 32]);
    let fh_md = l.md(&format!(
        "<FHcomment><TX>written by hils</TX><tool_id>hils</tool_id><tool_vendor>brake HILS project</tool_vendor><tool_version>{}</tool_version></FHcomment>",
        env!("CARGO_PKG_VERSION")
    ));
    let fh = l.block(b"FH", &[0, fh_md], &[0u8; 16]);
    let hd_md = l.md(&header_xml(comment, metadata));
    // Channels, last first (each links to the next).
    let record_bytes: u32 = 8 + columns.iter().map(|c| c.values.bytes()).sum::<u32>();
    let mut next = 0u64;
    let mut offset = record_bytes;
    for c in columns.iter().rev() {
        offset -= c.values.bytes();
        let (data_type, bits, cc) = match &c.values {
            ColumnValues::Num(_) => (4u8, 64u32, 0u64),
            ColumnValues::Text { texts, .. } => (0, 32, vtab(&mut l, texts)),
        };
        let (name, unit, com) = (l.tx(c.name), l.tx(c.unit), l.tx(c.comment));
        next = l.block(
            b"CN",
            &[next, 0, name, 0, cc, 0, unit, com],
            &cn_data(0, 0, data_type, offset, bits),
        );
    }
    let (name, unit, com) = (
        l.tx("t_s"),
        l.tx("s"),
        l.tx("time since the start of the log"),
    );
    let master = l.block(
        b"CN",
        &[next, 0, name, 0, 0, 0, unit, com],
        &cn_data(2, 1, 4, 0, 64),
    );
    let mut cg_data = Vec::new();
    cg_data.extend_from_slice(&0u64.to_le_bytes());
    cg_data.extend_from_slice(&(rows as u64).to_le_bytes());
    cg_data.extend_from_slice(&[0u8; 8]);
    cg_data.extend_from_slice(&record_bytes.to_le_bytes());
    cg_data.extend_from_slice(&0u32.to_le_bytes());
    let cg = l.block(b"CG", &[0, master, 0, 0, 0, 0], &cg_data);
    let dg_at = l.addr();
    let dt_at = dg_at + 24 + 4 * 8 + 8;
    let dg = l.block(b"DG", &[0, cg, dt_at, 0], &[0u8; 8]);
    debug_assert_eq!(dg, dg_at);
    // HD links: first DG, file history, channel hierarchy, attachments, events, comment.
    for (i, link) in [dg, fh, 0, 0, 0, hd_md].iter().enumerate() {
        let at = hd as usize + 24 + 8 * i;
        l.buf[at..at + 8].copy_from_slice(&link.to_le_bytes());
    }
    out.write_all(&l.buf)?;
    // DT: header, then the records.
    let data_len = rows as u64 * record_bytes as u64;
    let mut head = Vec::with_capacity(24);
    head.extend_from_slice(b"##DT\0\0\0\0");
    head.extend_from_slice(&(24 + data_len).to_le_bytes());
    head.extend_from_slice(&0u64.to_le_bytes());
    out.write_all(&head)?;
    let mut out = std::io::BufWriter::new(out);
    for r in 0..rows {
        out.write_all(&time_s[r].to_le_bytes())?;
        for c in columns {
            match &c.values {
                ColumnValues::Num(v) => out.write_all(&v[r].to_le_bytes())?,
                ColumnValues::Text { codes, .. } => out.write_all(&codes[r].to_le_bytes())?,
            }
        }
    }
    // Blocks end on 8-byte boundaries.
    let pad = ((8 - data_len % 8) % 8) as usize;
    out.write_all(&[0u8; 8][..pad])?;
    out.flush()
}
