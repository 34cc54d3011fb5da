//! The block level of ASAM MDF 4.1/4.2: the file as a source of bytes at offsets (a file
//! read piecewise, or bytes in memory), block headers (`##XX`, length, links) checked
//! against the file's size, and the text of TX and MD blocks.
//!
//! Every address and length read from the file is checked before use: a block pointer
//! outside the file, a block that runs past the end (a truncated file), a block of the
//! wrong kind where the format wants another, or a linked list that loops is an error,
//! never a panic.

use std::cell::RefCell;
use std::io::{Read, Seek, SeekFrom};

/// Bytes of a block header: id (4), reserved (4), length (8), link count (8).
pub const HEADER_BYTES: u64 = 24;

/// Most links a non-list block may have (a DL block may have more, bounded by the file).
const MAX_LINKS: u64 = 1 << 24;

/// Largest metadata block (TX, MD, CC, ...) read whole: 64 MiB.
const MAX_META_BYTES: u64 = 64 << 20;

/// Where the file's bytes come from.
pub trait ReadAt {
    /// Size of the file, bytes.
    fn size(&self) -> u64;
    /// Fills `buf` from `offset` (the caller has checked the range).
    fn read_at(&self, offset: u64, buf: &mut [u8]) -> std::io::Result<()>;
}

/// A file's bytes in memory.
pub struct Memory<'a>(pub &'a [u8]);

impl ReadAt for Memory<'_> {
    fn size(&self) -> u64 {
        self.0.len() as u64
    }
    fn read_at(&self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        let start = usize::try_from(offset).map_err(std::io::Error::other)?;
        let src = start
            .checked_add(buf.len())
            .and_then(|end| self.0.get(start..end))
            .ok_or_else(|| std::io::Error::other("outside the bytes"))?;
        buf.copy_from_slice(src);
        Ok(())
    }
}

/// A file read piecewise (never held whole).
pub struct FileSource {
    file: RefCell<std::fs::File>,
    size: u64,
}

impl FileSource {
    pub fn new(file: std::fs::File) -> std::io::Result<Self> {
        let size = file.metadata()?.len();
        Ok(Self {
            file: RefCell::new(file),
            size,
        })
    }
}

impl ReadAt for FileSource {
    fn size(&self) -> u64 {
        self.size
    }
    fn read_at(&self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        let mut f = self.file.borrow_mut();
        f.seek(SeekFrom::Start(offset))?;
        f.read_exact(buf)
    }
}

/// A block: its id (`DG`, `CN`, ...), address, links and data section.
#[derive(Clone, Debug)]
pub struct Block {
    pub id: [u8; 2],
    pub addr: u64,
    /// Total length (header, links, data), bytes.
    pub length: u64,
    pub links: Vec<u64>,
    /// The data section (empty for DT/DZ-like blocks read by [`Blocks::header`]).
    pub data: Vec<u8>,
}

impl Block {
    /// Link `i` (0 when the block has fewer links: an older format version).
    pub fn link(&self, i: usize) -> u64 {
        self.links.get(i).copied().unwrap_or(0)
    }

    /// Little-endian unsigned integer of `n` bytes at `at` in the data section (0 when the
    /// section is shorter: checked by [`Block::need`]).
    pub fn uint(&self, at: usize, n: usize) -> u64 {
        let mut v = 0u64;
        for k in (0..n).rev() {
            v = (v << 8) | *self.data.get(at + k).unwrap_or(&0) as u64;
        }
        v
    }

    pub fn f64(&self, at: usize) -> f64 {
        f64::from_bits(self.uint(at, 8))
    }

    /// The block's kind for messages: `DG`.
    pub fn kind(&self) -> String {
        String::from_utf8_lossy(&self.id).into_owned()
    }

    /// Fails when the data section is shorter than `bytes`.
    pub fn need(&self, bytes: usize) -> Result<(), String> {
        if self.data.len() < bytes {
            return Err(format!(
                "{} block at {:#x}: data section of {} bytes, the format needs {bytes}",
                self.kind(),
                self.addr,
                self.data.len()
            ));
        }
        Ok(())
    }
}

/// The file's blocks.
pub struct Blocks<'a> {
    pub src: &'a dyn ReadAt,
}

impl<'a> Blocks<'a> {
    pub fn new(src: &'a dyn ReadAt) -> Self {
        Self { src }
    }

    /// `len` bytes at `offset`, or the error saying they are outside the file.
    pub fn bytes(&self, offset: u64, len: u64, what: &str) -> Result<Vec<u8>, String> {
        let size = self.src.size();
        match offset.checked_add(len) {
            Some(end) if end <= size => {}
            _ => {
                return Err(format!(
                    "{what} at {offset:#x} (+{len} bytes) lies outside the file ({size} bytes): \
                     a truncated file or a bad block pointer"
                ));
            }
        }
        let mut buf = vec![0u8; len as usize];
        self.src
            .read_at(offset, &mut buf)
            .map_err(|e| format!("cannot read {what} at {offset:#x}: {e}"))?;
        Ok(buf)
    }

    /// The header and links of the block at `addr` (its data section not read), checked
    /// to be one of `kinds` (`b"DG"`) and to lie inside the file.
    pub fn header(&self, addr: u64, kinds: &[&[u8; 2]]) -> Result<Block, String> {
        let names: Vec<String> = kinds
            .iter()
            .map(|k| String::from_utf8_lossy(&k[..]).into_owned())
            .collect();
        let what = format!("block ({})", names.join("/"));
        let h = self.bytes(addr, HEADER_BYTES, &what)?;
        let kind = [h[2], h[3]];
        if &h[0..2] != b"##" || !kinds.iter().any(|k| **k == kind) {
            return Err(format!(
                "at {addr:#x}: expected a {} block, found {}",
                names.join(" or "),
                block_id_text(&h[0..4])
            ));
        }
        let length = u64::from_le_bytes(h[8..16].try_into().unwrap_or_default());
        let link_count = u64::from_le_bytes(h[16..24].try_into().unwrap_or_default());
        let name = String::from_utf8_lossy(&kind).into_owned();
        if link_count > MAX_LINKS || HEADER_BYTES + 8 * link_count > length {
            return Err(format!(
                "{name} block at {addr:#x}: length {length} cannot hold {link_count} links"
            ));
        }
        // The whole block inside the file.
        self.bytes_in_file(addr, length, &name)?;
        let raw = self.bytes(addr + HEADER_BYTES, 8 * link_count, &name)?;
        let links = raw
            .chunks_exact(8)
            .map(|c| u64::from_le_bytes(c.try_into().unwrap_or_default()))
            .collect();
        Ok(Block {
            id: kind,
            addr,
            length,
            links,
            data: Vec::new(),
        })
    }

    /// Whether `len` bytes from `addr` lie in the file (the error otherwise).
    fn bytes_in_file(&self, addr: u64, len: u64, name: &str) -> Result<(), String> {
        let size = self.src.size();
        match addr.checked_add(len) {
            Some(end) if end <= size => Ok(()),
            _ => Err(format!(
                "{name} block at {addr:#x} of {len} bytes runs past the end of the file \
                 ({size} bytes): a truncated file or a bad block pointer"
            )),
        }
    }

    /// The block at `addr` with its data section (a metadata block: at most 64 MiB).
    pub fn block(&self, addr: u64, kinds: &[&[u8; 2]]) -> Result<Block, String> {
        let mut b = self.header(addr, kinds)?;
        let start = HEADER_BYTES + 8 * b.links.len() as u64;
        let len = b.length - start;
        if len > MAX_META_BYTES {
            return Err(format!(
                "{} block at {addr:#x}: {len} bytes of data, more than a block of its kind holds",
                b.kind()
            ));
        }
        b.data = self.bytes(addr + start, len, &b.kind())?;
        Ok(b)
    }

    /// The text of a TX block, or the XML of an MD block (None for link 0).
    pub fn text(&self, addr: u64) -> Result<Option<Text>, String> {
        if addr == 0 {
            return Ok(None);
        }
        let b = self.block(addr, &[b"TX", b"MD"])?;
        let end = b.data.iter().position(|&c| c == 0).unwrap_or(b.data.len());
        let s = String::from_utf8_lossy(&b.data[..end]).into_owned();
        Ok(Some(if &b.id == b"TX" {
            Text::Plain(s)
        } else {
            Text::Xml(s)
        }))
    }

    /// The plain text of a TX block, or the `<TX>` element of an MD block.
    pub fn plain_text(&self, addr: u64) -> Result<String, String> {
        Ok(match self.text(addr)? {
            None => String::new(),
            Some(Text::Plain(s)) => s,
            Some(Text::Xml(x)) => xml_tx(&x).unwrap_or_default(),
        })
    }

    /// The addresses of a linked list of blocks (`next` = the index of the link to the
    /// next), checked for loops and a bound on its length.
    pub fn chain(
        &self,
        first: u64,
        kinds: &[&[u8; 2]],
        next: usize,
        what: &str,
    ) -> Result<Vec<Block>, String> {
        let mut out = Vec::new();
        let mut seen = std::collections::HashSet::new();
        let mut addr = first;
        while addr != 0 {
            if !seen.insert(addr) {
                return Err(format!("the list of {what} loops (at {addr:#x})"));
            }
            // Each block takes at least a header: a list longer than the file is corrupt.
            if out.len() as u64 > self.src.size() / HEADER_BYTES {
                return Err(format!("the list of {what} is longer than the file"));
            }
            let b = self.block(addr, kinds)?;
            addr = b.link(next);
            out.push(b);
        }
        Ok(out)
    }
}

/// The text of a TX or MD block.
#[derive(Clone, Debug, PartialEq)]
pub enum Text {
    Plain(String),
    Xml(String),
}

/// The text of the first `<TX>` element of an MD block's XML.
pub fn xml_tx(xml: &str) -> Option<String> {
    let doc = roxmltree::Document::parse(xml).ok()?;
    doc.descendants()
        .find(|n| n.has_tag_name("TX"))
        .map(|n| n.text().unwrap_or("").trim().to_string())
}

/// The `<e name="key">value</e>` properties of an MD block's `common_properties`, in
/// order (an error when the XML does not parse). A property inside `<tree name="..">` or
/// `<list name="..">` sections is keyed by their path (`Vehicle/name`), so that two
/// sections' equal names are two keys.
pub fn xml_properties(xml: &str) -> Result<Vec<(String, String)>, String> {
    let doc = roxmltree::Document::parse(xml).map_err(|e| format!("comment XML: {e}"))?;
    Ok(doc
        .descendants()
        .filter(|n| n.has_tag_name("e"))
        .filter_map(|n| {
            let name = n.attribute("name")?.trim();
            let mut sections: Vec<&str> = n
                .ancestors()
                .skip(1)
                .filter(|a| a.has_tag_name("tree") || a.has_tag_name("list"))
                .filter_map(|a| a.attribute("name"))
                .map(str::trim)
                .collect();
            sections.reverse();
            sections.push(name);
            Some((
                sections.join("/"),
                n.text().unwrap_or("").trim().to_string(),
            ))
        })
        .collect())
}

/// A block id as read, for a message: `##DG`, or its bytes in hex when they are not
/// printable ASCII (a link into the middle of a block).
fn block_id_text(id: &[u8]) -> String {
    if id.iter().all(|b| b.is_ascii_graphic()) {
        format!("`{}`", String::from_utf8_lossy(id))
    } else {
        let hex: Vec<String> = id.iter().map(|b| format!("{b:02x}")).collect();
        format!("no block (bytes {})", hex.join(" "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A link into the middle of a block shows the bytes found, not raw bytes as text.
    #[test]
    fn a_block_id_that_is_no_block_is_shown_in_hex() {
        assert_eq!(block_id_text(b"##DG"), "`##DG`");
        assert_eq!(
            block_id_text(&[3, 0, 0xff, 0]),
            "no block (bytes 03 00 ff 00)"
        );
    }

    /// Properties in nested trees (a tool's device or vehicle sections) are keyed by their
    /// tree path: two trees' `name` are two keys, not one key given twice.
    #[test]
    fn nested_properties_are_keyed_by_their_tree() {
        let xml = r#"<HDcomment><TX>t</TX><common_properties><e name="rail">wet</e>
            <tree name="Vehicle"><e name="name">A</e><tree name="Bogie"><e name="name">B1</e></tree></tree>
            <tree name="Driver"><e name="name">B</e></tree></common_properties></HDcomment>"#;
        let p = xml_properties(xml).unwrap();
        let keys: Vec<&str> = p.iter().map(|(k, _)| k.as_str()).collect();
        assert_eq!(
            keys,
            ["rail", "Vehicle/name", "Vehicle/Bogie/name", "Driver/name"]
        );
        assert_eq!(p[0].1, "wet");
    }
}
