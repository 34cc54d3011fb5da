//! The records of a channel group: the data group's blocks (DT, DL lists, HL headers, DZ
//! deflate with or without transposition) as one byte stream read piecewise, split into
//! records (by record id in an unsorted group), and the asked channels decoded.

use super::blocks::{Blocks, HEADER_BYTES};
use super::convert::Phys;
use super::vlsd::{SignalData, VlsdRecords, entry_text, text_of};
use super::{ChannelInfo, Group, Mdf4};
use crate::measured::TextColumn;

/// Most distinct texts a text channel may hold (as the CSV reader's text columns).
const MAX_DISTINCT_TEXTS: usize = 1024;

/// Bytes read from a DT block at a time.
const CHUNK_BYTES: u64 = 1 << 20;

/// Largest inflated DZ block: 1 GiB (tools write blocks of a few MiB).
const MAX_INFLATED_BYTES: u64 = 1 << 30;

/// A piece of the data stream.
#[derive(Clone, Debug)]
pub(super) enum Piece {
    /// Raw bytes at an address.
    Raw { addr: u64, len: u64 },
    /// A DZ block: its compressed bytes, how they were packed, the inflated length.
    Zipped {
        addr: u64,
        len: u64,
        zip_type: u8,
        columns: u32,
        inflated: u64,
    },
}

impl Piece {
    /// Bytes the piece holds in the stream (a DZ block's: unpacked).
    pub(super) fn stream_len(&self) -> u64 {
        match *self {
            Piece::Raw { len, .. } => len,
            Piece::Zipped { inflated, .. } => inflated,
        }
    }
}

/// Record data: DT (or DV) blocks.
pub(super) const RECORD_BLOCKS: &[&[u8; 2]] = &[b"DT", b"DV"];

/// The pieces of the stream that starts at `addr`: one block of the kinds `data` (record
/// data: [`RECORD_BLOCKS`]; signal data: SD), a DZ block holding one, or a DL list (an HL
/// header's) of them.
pub(super) fn pieces(blocks: &Blocks, addr: u64, data: &[&[u8; 2]]) -> Result<Vec<Piece>, String> {
    let mut out = Vec::new();
    if addr == 0 {
        return Ok(out);
    }
    let mut kinds = data.to_vec();
    kinds.extend_from_slice(&[b"DZ", b"DL", b"HL"]);
    let head = blocks.header(addr, &kinds)?;
    match &head.id {
        b"HL" => {
            let hl = blocks.block(addr, &[b"HL"])?;
            return pieces_of_list(blocks, hl.link(0), data, &mut out).map(|_| out);
        }
        b"DL" => pieces_of_list(blocks, addr, data, &mut out)?,
        _ => out.push(piece(blocks, addr, data)?),
    }
    Ok(out)
}

/// The pieces of a DL list (and the lists it links to).
fn pieces_of_list(
    blocks: &Blocks,
    first: u64,
    data: &[&[u8; 2]],
    out: &mut Vec<Piece>,
) -> Result<(), String> {
    for dl in blocks.chain(first, &[b"DL"], 0, "data lists")? {
        for &a in dl.links.iter().skip(1) {
            if a != 0 {
                out.push(piece(blocks, a, data)?);
            }
        }
    }
    Ok(())
}

/// One data block (of the kinds `data`, or a DZ block holding one) as a piece.
fn piece(blocks: &Blocks, addr: u64, data: &[&[u8; 2]]) -> Result<Piece, String> {
    let mut kinds = data.to_vec();
    kinds.push(b"DZ");
    let h = blocks.header(addr, &kinds)?;
    let start = addr + HEADER_BYTES + 8 * h.links.len() as u64;
    let len = h.length - HEADER_BYTES - 8 * h.links.len() as u64;
    if &h.id != b"DZ" {
        return Ok(Piece::Raw { addr: start, len });
    }
    let d = blocks.block(addr, &[b"DZ"])?;
    d.need(24)?;
    let (org, zip_type) = (&d.data[0..2], d.data[2]);
    if !data.iter().any(|k| &k[..] == org) {
        return Err(format!(
            "DZ block at {addr:#x}: holds a `{}` block where the format wants {}",
            String::from_utf8_lossy(org),
            data.iter()
                .map(|k| String::from_utf8_lossy(&k[..]).into_owned())
                .collect::<Vec<_>>()
                .join(" or ")
        ));
    }
    let inflated = d.uint(8, 8);
    let zipped = d.uint(16, 8);
    if zipped > len - 24 || inflated > MAX_INFLATED_BYTES || zip_type > 1 {
        return Err(format!(
            "DZ block at {addr:#x}: zip type {zip_type}, {zipped} bytes packed into {} ({inflated} \
             unpacked): not a deflate block this reader takes",
            len - 24
        ));
    }
    Ok(Piece::Zipped {
        addr: start + 24,
        len: zipped,
        zip_type,
        columns: d.uint(4, 4) as u32,
        inflated,
    })
}

/// Inflates a DZ piece and undoes its transposition.
/// Why deflate data did not unpack, in words (never the decoder's debug form, which
/// carries the whole partial output).
fn inflate_failure(status: miniz_oxide::inflate::TINFLStatus) -> &'static str {
    use miniz_oxide::inflate::TINFLStatus as S;
    match status {
        S::Adler32Mismatch => "checksum mismatch",
        S::HasMoreOutput => "it unpacks to more than the block says",
        S::NeedsMoreInput | S::FailedCannotMakeProgress => "it ends early",
        _ => "not valid deflate data",
    }
}

pub(super) fn inflate(blocks: &Blocks, p: &Piece) -> Result<Vec<u8>, String> {
    let Piece::Zipped {
        addr,
        len,
        zip_type,
        columns,
        inflated,
    } = *p
    else {
        return Ok(Vec::new());
    };
    let packed = blocks.bytes(addr, len, "DZ data")?;
    let out = miniz_oxide::inflate::decompress_to_vec_zlib_with_limit(&packed, inflated as usize)
        .map_err(|e| {
        format!(
            "DZ block at {addr:#x}: its compressed data is damaged ({})",
            inflate_failure(e.status)
        )
    })?;
    if out.len() as u64 != inflated {
        return Err(format!(
            "DZ block at {addr:#x}: unpacks to {} bytes, the block says {inflated}",
            out.len()
        ));
    }
    if zip_type == 1 && columns > 0 {
        return Ok(untranspose(&out, columns as usize));
    }
    Ok(out)
}

/// Undoes MDF4's transposition: the first `rows * columns` bytes were stored column by
/// column (`columns` = record length); the rest as it was.
pub fn untranspose(data: &[u8], columns: usize) -> Vec<u8> {
    let rows = data.len() / columns.max(1);
    if rows == 0 {
        return data.to_vec();
    }
    let n = rows * columns;
    let mut out = vec![0u8; data.len()];
    for c in 0..columns {
        for r in 0..rows {
            out[r * columns + c] = data[c * rows + r];
        }
    }
    out[n..].copy_from_slice(&data[n..]);
    out
}

/// The data stream of a data group, read piece by piece.
struct Stream<'b, 'a> {
    blocks: &'b Blocks<'a>,
    pieces: Vec<Piece>,
    next_piece: usize,
    /// Offset within the current raw piece.
    raw_at: u64,
    buf: Vec<u8>,
    pos: usize,
}

impl<'b, 'a> Stream<'b, 'a> {
    fn new(blocks: &'b Blocks<'a>, addr: u64) -> Result<Self, String> {
        Ok(Self {
            blocks,
            pieces: pieces(blocks, addr, RECORD_BLOCKS)?,
            next_piece: 0,
            raw_at: 0,
            buf: Vec::new(),
            pos: 0,
        })
    }

    /// Appends the next chunk to the buffer (false at the end of the stream).
    fn refill(&mut self) -> Result<bool, String> {
        let Some(p) = self.pieces.get(self.next_piece).cloned() else {
            return Ok(false);
        };
        let chunk = match p {
            Piece::Raw { addr, len } => {
                let n = (len - self.raw_at).min(CHUNK_BYTES);
                let c = self.blocks.bytes(addr + self.raw_at, n, "record data")?;
                self.raw_at += n;
                if self.raw_at >= len {
                    self.next_piece += 1;
                    self.raw_at = 0;
                }
                c
            }
            Piece::Zipped { .. } => {
                self.next_piece += 1;
                inflate(self.blocks, &p)?
            }
        };
        self.buf.drain(..self.pos);
        self.pos = 0;
        self.buf.extend_from_slice(&chunk);
        Ok(true)
    }

    /// The next `n` bytes (None at the end; an error when the stream ends inside them).
    fn take(&mut self, n: usize) -> Result<Option<&[u8]>, String> {
        while self.buf.len() - self.pos < n {
            if !self.refill()? {
                if self.buf.len() == self.pos {
                    return Ok(None);
                }
                return Err(format!(
                    "the record data ends inside a record ({} of {n} bytes): a truncated file",
                    self.buf.len() - self.pos
                ));
            }
        }
        let s = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(Some(s))
    }
}

/// Decoded values of one channel: numbers (NaN where invalid) or texts (interned: each
/// distinct text once).
#[derive(Clone, Debug, PartialEq)]
pub enum Values {
    Num(Vec<f64>),
    Text(TextColumn),
}

impl Values {
    pub fn len(&self) -> usize {
        match self {
            Values::Num(v) => v.len(),
            Values::Text(v) => v.len(),
        }
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// An error about one channel (its name) or the group (empty name).
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelError {
    pub channel: String,
    pub message: String,
}

fn group_err(g: &Group, message: impl Into<String>) -> ChannelError {
    ChannelError {
        channel: String::new(),
        message: format!("{}: {}", g.label(), message.into()),
    }
}

/// Where a VLSD text channel's texts come from.
enum VlsdSource<'b, 'a> {
    /// Signal data, read by offset as the records come.
    Sd(SignalData<'b, 'a>),
    /// A VLSD channel group's records (in the same data stream): the records' offsets
    /// (None: an invalid sample) are looked up when the stream has been read.
    Cg {
        records: VlsdRecords,
        offsets: Vec<Option<u64>>,
    },
}

/// A channel with more distinct texts than a command or state channel has.
fn too_many_texts(ch: &ChannelInfo) -> ChannelError {
    ChannelError {
        channel: ch.name.clone(),
        message: format!(
            "more than {MAX_DISTINCT_TEXTS} distinct texts: not a command or state channel"
        ),
    }
}

/// An error of [`Mdf4::read_group_chunks`]: the file's (about a channel or the group), or
/// the one its caller's `each` returned.
#[derive(Debug)]
pub enum ChunkError<E> {
    File(ChannelError),
    Each(E),
}

impl<E> From<ChannelError> for ChunkError<E> {
    fn from(e: ChannelError) -> Self {
        ChunkError::File(e)
    }
}

/// A chunk of a group's records: the time of each (the master channel's values) and the
/// values of the channels asked for.
pub type Chunk = (Vec<f64>, Vec<Values>);

impl<'a> Mdf4<'a> {
    /// The time of every record of group `g` (s, from its master channel's values) and the
    /// values of its channels `wanted` (indices into `g.channels`).
    pub fn read_group(&self, g: usize, wanted: &[usize]) -> Result<Chunk, ChannelError> {
        let never = |_: Chunk| -> Result<(), ChannelError> { Ok(()) };
        self.read_group_chunks(g, wanted, usize::MAX, never)
            .map_err(|e| match e {
                ChunkError::File(e) | ChunkError::Each(e) => e,
            })
    }

    /// [`Mdf4::read_group`] in chunks of `chunk_rows` records, for groups too large to
    /// hold: each full chunk is handed to `each`, then dropped; the last (partial, maybe
    /// empty) chunk is returned. Memory is the chunk and the read window (1 MiB of record
    /// data or one DZ block), whatever the group's length. A text channel whose texts sit
    /// in a VLSD channel group (known only at the data's end) makes one chunk of the group.
    pub fn read_group_chunks<E>(
        &self,
        g: usize,
        wanted: &[usize],
        chunk_rows: usize,
        mut each: impl FnMut(Chunk) -> Result<(), E>,
    ) -> Result<Chunk, ChunkError<E>> {
        let group = &self.groups[g];
        let master = group
            .time_master()
            .ok_or_else(|| group_err(group, "no time master channel"))?;
        let mut idx = vec![master];
        idx.extend_from_slice(wanted);
        let decoders = idx
            .iter()
            .map(|&i| Decoder::new(group, &group.channels[i]))
            .collect::<Result<Vec<_>, _>>()?;
        let mut sources = decoders
            .iter()
            .map(|d| d.vlsd.then(|| self.vlsd_source(group, d.ch)).transpose())
            .collect::<Result<Vec<_>, _>>()?;
        let chunk_rows = match sources
            .iter()
            .any(|s| matches!(s, Some(VlsdSource::Cg { .. })))
        {
            true => usize::MAX,
            false => chunk_rows.max(1),
        };
        // Room for the group's records (its count, bounded by what the file can hold).
        let record = (group.data_bytes + group.inval_bytes).max(1) as u64;
        let room = group.cycle_count.min(self.blocks.src.size() / record) as usize;
        let room = room.min(chunk_rows);
        let mut out: Vec<Values> = decoders.iter().map(|d| d.empty(room)).collect();
        let sizes = self.record_sizes(group.dg);
        let mut stream =
            Stream::new(&self.blocks, group.data_addr).map_err(|e| group_err(group, e))?;
        let id_bytes = group.rec_id_size as usize;
        let own = (group.data_bytes + group.inval_bytes) as usize;
        let mut index = 0u64;
        loop {
            let rid = if id_bytes == 0 {
                group.record_id
            } else {
                match stream.take(id_bytes).map_err(|e| group_err(group, e))? {
                    None => break,
                    Some(b) => le(b),
                }
            };
            let size = if id_bytes == 0 {
                own
            } else {
                self.size_of(&sizes, rid, &mut stream)
                    .map_err(|e| group_err(group, e))?
            };
            let Some(rec) = stream
                .take(size)
                .map_err(
                    |e| match sizes.iter().any(|&(id, n)| id == rid && n.is_none()) {
                        true => format!(
                            "a VLSD record (id {rid}) says its value has {size} bytes, more than \
                         the data holds: a damaged or truncated file"
                        ),
                        false => e,
                    },
                )
                .map_err(|e| group_err(group, e))?
            else {
                break;
            };
            if rid != group.record_id {
                collect_vlsd_records(&decoders, &mut sources, rid, rec)?;
                continue;
            }
            if rec.len() < own {
                return Err(ChunkError::File(group_err(
                    group,
                    format!(
                        "record {} has {} bytes, the group's records {own}: two groups share \
                         record id {rid}",
                        index + 1,
                        rec.len()
                    ),
                )));
            }
            decode_record(&decoders, &mut sources, rec, index, &mut out)?;
            index += 1;
            if out[0].len() >= chunk_rows {
                let full = decoders.iter().map(|d| d.empty(room)).collect();
                each(time_and_values(group, std::mem::replace(&mut out, full))?)
                    .map_err(ChunkError::Each)?;
            }
        }
        if index != group.cycle_count {
            return Err(ChunkError::File(group_err(
                group,
                format!(
                    "{index} records in the data, the group says {}: a truncated or damaged file",
                    group.cycle_count
                ),
            )));
        }
        for ((d, s), o) in decoders.iter().zip(sources).zip(out.iter_mut()) {
            if let Some(VlsdSource::Cg { records, offsets }) = s {
                d.resolve(&records, &offsets, o)?;
            }
        }
        Ok(time_and_values(group, out)?)
    }

    /// The source of VLSD text channel `ch` of `group`: its signal data, or (MDF 4.2) the
    /// VLSD channel group of the same data group its `cn_data` points to.
    fn vlsd_source<'b>(
        &'b self,
        group: &Group,
        ch: &ChannelInfo,
    ) -> Result<VlsdSource<'b, 'a>, ChannelError> {
        let err = |m: String| ChannelError {
            channel: ch.name.clone(),
            message: m,
        };
        let sd = |addr| SignalData::new(&self.blocks, addr).map(VlsdSource::Sd);
        if ch.data_addr == 0 {
            return sd(0).map_err(err);
        }
        let head = self
            .blocks
            .header(ch.data_addr, &[b"SD", b"DZ", b"DL", b"HL", b"CG"])
            .map_err(|e| err(format!("its signal data: {e}")))?;
        if &head.id != b"CG" {
            return sd(ch.data_addr).map_err(|e| err(format!("its signal data: {e}")));
        }
        let vlsd_group = self.groups.iter().find(|v| v.addr == ch.data_addr);
        match vlsd_group {
            Some(v) if v.is_vlsd() && v.dg == group.dg && group.rec_id_size > 0 => {
                Ok(VlsdSource::Cg {
                    records: VlsdRecords::new(v.record_id, ch.data_type, v.cycle_count),
                    offsets: Vec::new(),
                })
            }
            _ => Err(err(format!(
                "its signal data points to a channel group at {:#x} that is not a VLSD channel \
                 group of its unsorted data group",
                ch.data_addr
            ))),
        }
    }

    /// Record sizes of the groups of data group `dg` by record id (None: a VLSD group,
    /// whose records carry their length).
    fn record_sizes(&self, dg: usize) -> Vec<(u64, Option<usize>)> {
        self.groups
            .iter()
            .filter(|g| g.dg == dg)
            .map(|g| {
                let size = (!g.is_vlsd()).then_some((g.data_bytes + g.inval_bytes) as usize);
                (g.record_id, size)
            })
            .collect()
    }

    /// The size of the record with id `rid` (a VLSD record's from its length prefix).
    fn size_of(
        &self,
        sizes: &[(u64, Option<usize>)],
        rid: u64,
        stream: &mut Stream,
    ) -> Result<usize, String> {
        match sizes.iter().find(|(id, _)| *id == rid) {
            Some((_, Some(n))) => Ok(*n),
            Some((_, None)) => match stream.take(4)? {
                Some(b) => Ok(le(b) as usize),
                None => Err("the record data ends inside a record: a truncated file".into()),
            },
            None => Err(format!(
                "record id {rid} belongs to no channel group of the data group"
            )),
        }
    }
}

/// The master channel's values (the first of `out`) as times, and the other channels'.
fn time_and_values(group: &Group, mut out: Vec<Values>) -> Result<Chunk, ChannelError> {
    match out.remove(0) {
        Values::Num(t) => Ok((t, out)),
        Values::Text(_) => Err(group_err(group, "the time master is a text")),
    }
}

/// An MDF4 data type (`cn_data_type`) for messages.
fn data_type_name(data_type: u8) -> &'static str {
    match data_type {
        0 | 1 => "unsigned integer",
        2 | 3 => "signed integer",
        4 | 5 => "float",
        6 => "Latin-1 string",
        7 => "UTF-8 string",
        8 | 9 => "UTF-16 string",
        10 => "byte array",
        11 | 12 => "MIME sample or stream",
        13 | 14 => "CANopen date or time",
        15 | 16 => "complex number",
        _ => "value of an unknown data type",
    }
}

/// A little-endian unsigned integer of up to 8 bytes.
fn le(b: &[u8]) -> u64 {
    b.iter().rev().fold(0u64, |v, &x| (v << 8) | x as u64)
}

/// Decodes record `rec` (number `index` of its group) into the channels' values.
fn decode_record(
    decoders: &[Decoder],
    sources: &mut [Option<VlsdSource>],
    rec: &[u8],
    index: u64,
    out: &mut [Values],
) -> Result<(), ChannelError> {
    for ((d, s), o) in decoders.iter().zip(sources.iter_mut()).zip(out.iter_mut()) {
        match s {
            Some(s) => d.push_vlsd(rec, index, s, o)?,
            None => d.push(rec, index, o),
        }
        if let Values::Text(t) = o {
            if t.values.len() > MAX_DISTINCT_TEXTS {
                return Err(too_many_texts(d.ch));
            }
        }
    }
    Ok(())
}

/// Takes record `rec` of another group (id `rid`) as an entry of the VLSD channel groups
/// the decoded channels read.
fn collect_vlsd_records(
    decoders: &[Decoder],
    sources: &mut [Option<VlsdSource>],
    rid: u64,
    rec: &[u8],
) -> Result<(), ChannelError> {
    for (d, s) in decoders.iter().zip(sources.iter_mut()) {
        if let Some(VlsdSource::Cg { records, .. }) = s {
            if records.record_id == rid {
                records.push(rec);
                if records.texts.values.len() > MAX_DISTINCT_TEXTS {
                    return Err(too_many_texts(d.ch));
                }
            }
        }
    }
    Ok(())
}

/// How one channel's value is taken out of a record.
struct Decoder<'c> {
    ch: &'c ChannelInfo,
    /// Byte range of the value in the record.
    start: usize,
    bytes: usize,
    /// Invalidation bit (byte, mask) in the record.
    invalid: Option<(usize, u8)>,
    all_invalid: bool,
    text: bool,
    /// A VLSD text: the record holds the offset of its entry in the signal data.
    vlsd: bool,
}

impl<'c> Decoder<'c> {
    fn new(g: &Group, ch: &'c ChannelInfo) -> Result<Self, ChannelError> {
        let err = |m: String| ChannelError {
            channel: ch.name.clone(),
            message: m,
        };
        let supported = match ch.data_type {
            0..=3 => ch.bit_count >= 1 && ch.bit_count <= 64,
            4 | 5 => ch.bit_count == 32 || ch.bit_count == 64,
            6..=9 => ch.bit_count % 8 == 0 && ch.bit_count > 0,
            _ => false,
        };
        let vlsd = ch.cn_type == 1;
        let offset_ok = ch.bit_offset == 0 && ch.bit_count % 8 == 0 && ch.bit_count <= 64;
        if vlsd && !(matches!(ch.data_type, 6..=9) && offset_ok) {
            return Err(err(format!(
                "a variable-length {} (VLSD signal data) is not read by this reader (it reads \
                 variable-length texts with byte-aligned offsets): store it as fixed-length, or \
                 as numbers with a value-to-text conversion",
                data_type_name(ch.data_type)
            )));
        }
        if !supported {
            return Err(err(format!(
                "a {} of {} bits (MDF4 data type {}) is not read by this reader",
                data_type_name(ch.data_type),
                ch.bit_count,
                ch.data_type
            )));
        }
        if let super::convert::Conversion::Unsupported(t) = ch.conversion {
            return Err(err(format!(
                "its conversion, {} (MDF4 conversion type {t}), is not read by this reader",
                super::convert::type_name(t)
            )));
        }
        let be_unaligned =
            matches!(ch.data_type, 1 | 3 | 5) && (ch.bit_offset != 0 || ch.bit_count % 8 != 0);
        if be_unaligned {
            return Err(err(
                "big-endian value not on byte boundaries: not read".into()
            ));
        }
        // The format's bit offset is 0-7; floats and strings start on a byte.
        if ch.bit_offset > 7 || (ch.data_type >= 4 && ch.bit_offset != 0) {
            return Err(err(format!(
                "bit offset {} for data type {}: not a valid channel",
                ch.bit_offset, ch.data_type
            )));
        }
        let bytes = (ch.bit_offset as usize + ch.bit_count as usize).div_ceil(8);
        let start = ch.byte_offset as usize;
        let virtual_ch = ch.cn_type == 3 || ch.cn_type == 6;
        if !virtual_ch && start + bytes > g.data_bytes as usize {
            return Err(err(format!(
                "its value (bytes {start}..{}) lies outside the group's {}-byte records",
                start + bytes,
                g.data_bytes
            )));
        }
        let invalid = (ch.flags & 2 != 0 && g.inval_bytes > 0).then(|| {
            (
                g.data_bytes as usize + (ch.inval_bit_pos / 8) as usize,
                1u8 << (ch.inval_bit_pos % 8),
            )
        });
        if let Some((b, _)) = invalid {
            if b >= (g.data_bytes + g.inval_bytes) as usize {
                return Err(err("invalidation bit outside the record".into()));
            }
        }
        let text = matches!(ch.data_type, 6..=9) || ch.conversion.is_text();
        Ok(Self {
            ch,
            start,
            bytes,
            invalid,
            all_invalid: ch.flags & 1 != 0,
            text: text || vlsd,
            vlsd,
        })
    }

    fn empty(&self, room: usize) -> Values {
        if self.text {
            Values::Text(TextColumn::default())
        } else {
            Values::Num(Vec::with_capacity(room))
        }
    }

    /// Decodes the channel's value of record `rec` (number `index`) into `out`.
    fn push(&self, rec: &[u8], index: u64, out: &mut Values) {
        let invalid = self.all_invalid || self.invalid.is_some_and(|(b, m)| rec[b] & m != 0);
        // Not measured: empty, never a conversion's default value or text.
        let phys = if invalid && self.text {
            Phys::Text(String::new())
        } else if invalid {
            Phys::Num(f64::NAN)
        } else if self.ch.cn_type == 3 || self.ch.cn_type == 6 {
            self.ch.conversion.apply(index as f64)
        } else {
            match self.raw(&rec[self.start..self.start + self.bytes]) {
                Raw::Num(x) => self
                    .ch
                    .conversion
                    .apply_raw(x, matches!(self.ch.data_type, 4 | 5)),
                Raw::Text(s) => Phys::Text(s),
            }
        };
        match (out, phys) {
            (Values::Num(v), Phys::Num(x)) => v.push(x),
            (Values::Text(v), Phys::Text(s)) => v.push(&s),
            (Values::Text(v), Phys::Num(x)) => v.push(&if x.is_nan() {
                String::new()
            } else {
                format!("{x}")
            }),
            (Values::Num(v), Phys::Text(_)) => v.push(f64::NAN),
        }
    }

    /// Decodes the VLSD text of record `rec` (number `index`) from its source into `out`.
    fn push_vlsd(
        &self,
        rec: &[u8],
        index: u64,
        source: &mut VlsdSource,
        out: &mut Values,
    ) -> Result<(), ChannelError> {
        let invalid = self.all_invalid || self.invalid.is_some_and(|(b, m)| rec[b] & m != 0);
        let offset = (!invalid).then(|| le(&rec[self.start..self.start + self.bytes]));
        let text = match (source, offset) {
            (VlsdSource::Cg { offsets, .. }, _) => {
                offsets.push(offset);
                return Ok(());
            }
            (VlsdSource::Sd(_), None) => String::new(),
            (VlsdSource::Sd(sd), Some(at)) => {
                let entry = sd.entry(at).map_err(|e| self.record_err(index, e))?;
                entry_text(self.ch.data_type, &entry)
                    .map_err(|why| self.record_err(index, format!("{why}: a damaged file")))?
            }
        };
        if let Values::Text(t) = out {
            t.push(&text);
        }
        Ok(())
    }

    /// Fills `out` with the texts of the VLSD group's `records` at the records' `offsets`.
    fn resolve(
        &self,
        records: &VlsdRecords,
        offsets: &[Option<u64>],
        out: &mut Values,
    ) -> Result<(), ChannelError> {
        if records.count() != records.expected {
            return Err(ChannelError {
                channel: self.ch.name.clone(),
                message: format!(
                    "its VLSD channel group holds {} entries, the group says {}: a truncated \
                     or damaged file",
                    records.count(),
                    records.expected
                ),
            });
        }
        let Values::Text(t) = out else {
            return Ok(());
        };
        for (index, offset) in offsets.iter().enumerate() {
            let text = match offset {
                None => "",
                Some(at) => records
                    .text(*at)
                    .ok_or_else(|| {
                        self.record_err(
                            index as u64,
                            format!(
                                "its text's offset {at} is the start of no entry of its VLSD \
                             channel group ({} bytes of entries): a damaged file",
                                records.len_bytes()
                            ),
                        )
                    })?
                    .map_err(|why| {
                        self.record_err(index as u64, format!("{why}: a damaged file"))
                    })?,
            };
            t.push(text);
        }
        Ok(())
    }

    /// An error about the channel's value in record `index` (0-based) of its group.
    fn record_err(&self, index: u64, message: String) -> ChannelError {
        ChannelError {
            channel: self.ch.name.clone(),
            message: format!("record {} of its channel group: {message}", index + 1),
        }
    }

    /// The raw value in the channel's bytes.
    fn raw(&self, b: &[u8]) -> Raw {
        let ch = self.ch;
        match ch.data_type {
            0 | 2 => Raw::Num(self.int(le_u128(b))),
            1 | 3 => Raw::Num(self.int(be_u128(b))),
            4 | 5 => {
                let bits = if ch.data_type == 4 {
                    le_u128(b)
                } else {
                    be_u128(b)
                };
                Raw::Num(if ch.bit_count == 32 {
                    f32::from_bits(bits as u32) as f64
                } else {
                    f64::from_bits(bits as u64)
                })
            }
            _ => Raw::Text(text_of(ch.data_type, b)),
        }
    }

    /// An integer of `bit_count` bits at `bit_offset` of `v` (signed types sign-extended).
    fn int(&self, v: u128) -> f64 {
        let ch = self.ch;
        let v = v >> ch.bit_offset;
        let n = ch.bit_count;
        let mask = if n >= 128 {
            u128::MAX
        } else {
            (1u128 << n) - 1
        };
        let u = v & mask;
        if ch.data_type >= 2 && n > 0 && (u >> (n - 1)) & 1 == 1 {
            (u as i128 - (1i128 << n)) as f64
        } else {
            u as f64
        }
    }
}

enum Raw {
    Num(f64),
    Text(String),
}

fn le_u128(b: &[u8]) -> u128 {
    b.iter()
        .take(16)
        .rev()
        .fold(0u128, |v, &x| (v << 8) | x as u128)
}

fn be_u128(b: &[u8]) -> u128 {
    b.iter().take(16).fold(0u128, |v, &x| (v << 8) | x as u128)
}

#[cfg(test)]
mod tests {
    use super::super::convert::Conversion;

    /// Damaged deflate data is said in words: the decoder's error carries its whole partial
    /// output in its debug form (5 MB of numbers for a large block).
    #[test]
    fn damaged_deflate_data_is_said_in_words() {
        let data: Vec<u8> = (0..20_000u32)
            .flat_map(|i| (i % 251).to_le_bytes())
            .collect();
        let mut packed = miniz_oxide::deflate::compress_to_vec_zlib(&data, 6);
        let n = packed.len();
        packed[n - 2] ^= 0x55;
        let e = miniz_oxide::inflate::decompress_to_vec_zlib_with_limit(&packed, data.len())
            .unwrap_err();
        assert_eq!(inflate_failure(e.status), "checksum mismatch");
    }
    use super::*;

    fn channel(conversion: Conversion) -> ChannelInfo {
        ChannelInfo {
            name: "x".into(),
            unit: String::new(),
            comment: String::new(),
            cn_type: 0,
            sync_type: 0,
            data_type: 0,
            bit_offset: 0,
            byte_offset: 0,
            bit_count: 8,
            flags: 2,
            inval_bit_pos: 0,
            data_addr: 0,
            conversion,
        }
    }

    fn group() -> Group {
        Group {
            dg: 0,
            cg: 0,
            addr: 0,
            data_addr: 0,
            rec_id_size: 0,
            record_id: 0,
            cycle_count: 2,
            flags: 0,
            data_bytes: 1,
            inval_bytes: 1,
            acq_name: String::new(),
            comment: String::new(),
            channels: Vec::new(),
        }
    }

    /// An invalid sample is not measured: empty, whatever its conversion's default (a
    /// range table's default value, a text table's default text) would make of it.
    #[test]
    fn invalid_samples_stay_empty_through_every_conversion() {
        let ranges = Conversion::Ranges {
            ranges: vec![(0.0, 10.0, 1.0)],
            default: -1.0,
        };
        let texts = Conversion::Texts {
            keys: vec![(0.0, 0.0)],
            texts: vec!["REL".into()],
            default: "?".into(),
        };
        let g = group();
        let (cr, ct) = (channel(ranges), channel(texts));
        let (dr, dt) = (
            Decoder::new(&g, &cr).unwrap(),
            Decoder::new(&g, &ct).unwrap(),
        );
        let (mut vr, mut vt) = (dr.empty(2), dt.empty(2));
        for rec in [[5u8, 0], [5u8, 1]] {
            dr.push(&rec, 0, &mut vr);
            dt.push(&rec, 0, &mut vt);
        }
        let Values::Num(v) = vr else { panic!() };
        assert_eq!(v[0], 1.0);
        assert!(v[1].is_nan(), "invalid sample read as {}", v[1]);
        let Values::Text(t) = vt else { panic!() };
        let text = |i: usize| t.values[t.codes[i] as usize].clone();
        assert_eq!((text(0), text(1)), ("?".to_string(), String::new()));
    }

    /// What is not read is named in words: the data type, the conversion.
    #[test]
    fn unread_channels_are_named_in_words() {
        let g = group();
        let message = |ch: ChannelInfo| match Decoder::new(&g, &ch) {
            Err(e) => e.message,
            Ok(_) => panic!("read"),
        };
        let bytes = ChannelInfo {
            data_type: 10,
            bit_count: 24,
            ..channel(Conversion::Identity)
        };
        assert!(message(bytes).contains("a byte array of 24 bits"));
        let half = ChannelInfo {
            data_type: 4,
            bit_count: 16,
            ..channel(Conversion::Identity)
        };
        assert!(message(half).contains("a float of 16 bits"));
        let vlsd = ChannelInfo {
            cn_type: 1,
            data_type: 10,
            bit_count: 64,
            ..channel(Conversion::Identity)
        };
        assert!(message(vlsd).contains("variable-length byte array"));
        assert!(message(channel(Conversion::Unsupported(3))).contains("algebraic formula"));
    }

    #[test]
    fn untranspose_restores_records() {
        // Three records of 2 bytes, stored column by column, and one byte left over.
        let original = [1u8, 2, 3, 4, 5, 6, 7];
        let transposed = [1u8, 3, 5, 2, 4, 6, 7];
        assert_eq!(untranspose(&transposed, 2), original);
    }
}
