//! ASAM MDF 4.1/4.2 (`.mf4`): the project's own reader ([`Mdf4`]) and writer ([`write`]).
//!
//! # Reader
//!
//! What measurement tools (dSPACE ControlDesk, Vector CANape, ETAS INCA, HBM catman, imc)
//! write: data groups of one channel group (sorted) or of several with record ids
//! (unsorted); data in DT blocks, DL lists of them (HL headers included), and DZ blocks
//! (deflate, with or without transposition; `miniz_oxide`); a time master channel per
//! group (a real one, or a virtual one from the record index); integer and float channels
//! of either byte order, fixed-length strings, variable-length (VLSD) strings in signal
//! data or a VLSD channel group (`vlsd.rs`), invalidation bits; conversions
//! ([`convert`]); units (the channel's, else its conversion's); comments (TX or MD); the
//! file's metadata (the `<common_properties>` of the HD comment).
//!
//! The file is read piecewise ([`blocks::FileSource`]): the block tree first (small), then
//! only the records of the groups a caller asks for, with only the channels it asks for
//! decoded. Every pointer and length is checked against the file ([`blocks`]).
//!
//! Not read (an error naming the channel when a used channel needs it): variable-length
//! byte arrays and other VLSD uses than texts, algebraic conversions, bit fields, half
//! floats, big-endian values not on byte boundaries.

pub mod blocks;
pub mod convert;
pub mod data;
mod vlsd;
pub mod write;

use blocks::{Block, Blocks, ReadAt, Text, xml_properties};
use convert::Conversion;

/// One channel of a channel group.
#[derive(Clone, Debug)]
pub struct ChannelInfo {
    pub name: String,
    /// The unit as stored (the channel's, else its conversion's; empty: none).
    pub unit: String,
    pub comment: String,
    /// 0 fixed length, 1 VLSD, 2 master, 3 virtual master, 4 sync, 5 max length, 6 virtual data.
    pub cn_type: u8,
    /// 0 none, 1 time, 2 angle, 3 distance, 4 index.
    pub sync_type: u8,
    pub data_type: u8,
    pub bit_offset: u8,
    pub byte_offset: u32,
    pub bit_count: u32,
    pub flags: u32,
    pub inval_bit_pos: u32,
    /// `cn_data`: a VLSD channel's signal data (an SD block, a DL/DZ/HL list of them, or
    /// a VLSD channel group's CG block); 0 for none.
    pub data_addr: u64,
    pub conversion: Conversion,
}

impl ChannelInfo {
    /// A master channel (real or virtual).
    pub fn is_master(&self) -> bool {
        self.cn_type == 2 || self.cn_type == 3
    }
}

/// A channel group with its data group's layout.
#[derive(Clone, Debug)]
pub struct Group {
    /// 0-based data group and channel group within it.
    pub dg: usize,
    pub cg: usize,
    /// The CG block's address (what a VLSD channel's `cn_data` points to).
    pub addr: u64,
    /// The data group's first data block.
    pub data_addr: u64,
    /// Bytes of the record id before each record (0: sorted, one group).
    pub rec_id_size: u8,
    pub record_id: u64,
    pub cycle_count: u64,
    pub flags: u16,
    pub data_bytes: u32,
    pub inval_bytes: u32,
    pub acq_name: String,
    pub comment: String,
    pub channels: Vec<ChannelInfo>,
}

impl Group {
    /// The index of the group's time master channel, if any.
    pub fn time_master(&self) -> Option<usize> {
        self.channels
            .iter()
            .position(|c| c.is_master() && c.sync_type == 1)
    }

    /// A VLSD channel group (variable-length records of another group's channel).
    pub fn is_vlsd(&self) -> bool {
        self.flags & 1 != 0
    }

    /// `dg 2 / cg 1` for messages (1-based).
    pub fn label(&self) -> String {
        format!("data group {} / channel group {}", self.dg + 1, self.cg + 1)
    }
}

/// An MDF4 file's structure: version, metadata and channel groups.
pub struct Mdf4<'a> {
    pub blocks: Blocks<'a>,
    /// 410, 420, ...
    pub version: u16,
    /// `<common_properties>` of the HD comment, in order.
    pub metadata: Vec<(String, String)>,
    /// The HD comment's text (`<TX>`).
    pub comment: String,
    pub groups: Vec<Group>,
}

/// Whether `head` (the file's first bytes) is an MDF file's identification.
pub fn is_mdf(head: &[u8]) -> bool {
    head.starts_with(b"MDF     ") || head.starts_with(b"UnFinMF ")
}

impl<'a> Mdf4<'a> {
    /// Reads the identification, the header and every group's channels (not the data).
    pub fn open(src: &'a dyn ReadAt) -> Result<Self, String> {
        let blocks = Blocks::new(src);
        let id = blocks.bytes(0, 64, "identification block")?;
        if !is_mdf(&id) {
            return Err("not an MDF file (no `MDF     ` identification)".into());
        }
        let version = u16::from_le_bytes([id[28], id[29]]);
        if !(400..500).contains(&version) {
            return Err(format!(
                "MDF version {}.{:02}: only MDF 4 is read (save it as MDF 4.1 or 4.2)",
                version / 100,
                version % 100
            ));
        }
        if &id[0..8] == b"UnFinMF " {
            return Err(
                "an unfinalised MDF file (the logger stopped before closing it): finalise it \
                 with its tool first"
                    .into(),
            );
        }
        let hd = blocks.block(64, &[b"HD"])?;
        let (metadata, comment) = header_comment(&blocks, hd.link(5))?;
        let mut mdf = Mdf4 {
            blocks,
            version,
            metadata,
            comment,
            groups: Vec::new(),
        };
        mdf.groups = mdf.read_groups(hd.link(0))?;
        Ok(mdf)
    }

    fn read_groups(&self, first_dg: u64) -> Result<Vec<Group>, String> {
        let mut groups = Vec::new();
        let dgs = self.blocks.chain(first_dg, &[b"DG"], 0, "data groups")?;
        for (d, dg) in dgs.iter().enumerate() {
            dg.need(1)?;
            let rec_id_size = dg.data[0];
            if !matches!(rec_id_size, 0 | 1 | 2 | 4 | 8) {
                return Err(format!(
                    "data group {}: record id size {rec_id_size} (must be 0, 1, 2, 4 or 8)",
                    d + 1
                ));
            }
            let cgs = self
                .blocks
                .chain(dg.link(1), &[b"CG"], 0, "channel groups")?;
            if cgs.len() > 1 && rec_id_size == 0 {
                return Err(format!(
                    "data group {}: {} channel groups without record ids",
                    d + 1,
                    cgs.len()
                ));
            }
            for (c, cg) in cgs.iter().enumerate() {
                groups.push(self.group(d, c, dg, cg, rec_id_size)?);
            }
        }
        Ok(groups)
    }

    fn group(
        &self,
        dg_index: usize,
        cg_index: usize,
        dg: &Block,
        cg: &Block,
        rec_id_size: u8,
    ) -> Result<Group, String> {
        cg.need(32)?;
        let channels = self
            .blocks
            .chain(cg.link(1), &[b"CN"], 0, "channels")?
            .iter()
            .map(|cn| self.channel(cn))
            .collect::<Result<Vec<_>, String>>()?;
        Ok(Group {
            dg: dg_index,
            cg: cg_index,
            addr: cg.addr,
            data_addr: dg.link(2),
            rec_id_size,
            record_id: cg.uint(0, 8),
            cycle_count: cg.uint(8, 8),
            flags: cg.uint(16, 2) as u16,
            data_bytes: cg.uint(24, 4) as u32,
            inval_bytes: cg.uint(28, 4) as u32,
            acq_name: self.blocks.plain_text(cg.link(2))?,
            comment: self.blocks.plain_text(cg.link(5))?,
            channels,
        })
    }

    fn channel(&self, cn: &Block) -> Result<ChannelInfo, String> {
        cn.need(24)?;
        let name = self.blocks.plain_text(cn.link(2))?;
        let at = |e: String| format!("channel `{name}`: {e}");
        let (conversion, cc_unit) = convert::read(&self.blocks, cn.link(4)).map_err(at)?;
        let unit = self.blocks.plain_text(cn.link(6)).map_err(at)?;
        let unit = if unit.is_empty() { cc_unit } else { unit };
        let comment = self.blocks.plain_text(cn.link(7)).map_err(at)?;
        Ok(ChannelInfo {
            name,
            unit: unit.trim().to_string(),
            comment,
            cn_type: cn.data[0],
            sync_type: cn.data[1],
            data_type: cn.data[2],
            bit_offset: cn.data[3],
            byte_offset: cn.uint(4, 4) as u32,
            bit_count: cn.uint(8, 4) as u32,
            flags: cn.uint(12, 4) as u32,
            inval_bit_pos: cn.uint(16, 4) as u32,
            data_addr: cn.link(5),
            conversion,
        })
    }
}

/// The HD comment: its `<common_properties>` and its `<TX>` (a TX block: the text).
fn header_comment(blocks: &Blocks, addr: u64) -> Result<(Vec<(String, String)>, String), String> {
    match blocks.text(addr)? {
        None => Ok((Vec::new(), String::new())),
        Some(Text::Plain(s)) => Ok((Vec::new(), s)),
        Some(Text::Xml(x)) => Ok((
            xml_properties(&x).map_err(|e| format!("header comment: {e}"))?,
            blocks::xml_tx(&x).unwrap_or_default(),
        )),
    }
}
