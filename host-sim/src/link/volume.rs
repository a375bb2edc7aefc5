//! A volume as it goes on the wire, and the commands that put it on a
//! board.

use super::SendConfig;
use crate::volume::{Dims, LoadedVolume, Samples};
use anyhow::{Result, anyhow};
use isoscope_core::wire::{Levels, Message, SampleType};

/// A volume as it goes on the wire: little-endian samples, z slice by z
/// slice.
#[derive(Debug, Clone, PartialEq)]
pub struct WireVolume {
    /// Samples along x, y, z.
    pub dims: [u16; 3],
    /// The samples' type.
    pub sample_type: SampleType,
    /// Voxel spacing.
    pub spacing: [f32; 3],
    /// All samples, little-endian, x fastest.
    pub bytes: Vec<u8>,
}

impl WireVolume {
    /// The volume in its own sample type.
    ///
    /// # Errors
    /// An extent above 65535.
    pub fn from_loaded(v: &LoadedVolume) -> Result<Self> {
        Self::new(v.dims, &v.samples, v.spacing)
    }

    /// `samples` (x fastest) of a `dims` volume with voxel `spacing`.
    ///
    /// # Errors
    /// An extent above 65535.
    pub fn new(dims: Dims, samples: &Samples, spacing: [f32; 3]) -> Result<Self> {
        let Dims(nx, ny, nz) = dims;
        let d = |n: usize, axis: &str| {
            u16::try_from(n)
                .map_err(|_| anyhow!("the volume has {n} samples along {axis}; the protocol takes 65535"))
        };
        let dims = [d(nx, "x")?, d(ny, "y")?, d(nz, "z")?];
        let (sample_type, bytes) = match samples {
            Samples::U8(s) => (SampleType::U8, s.clone()),
            Samples::U16(s) => (SampleType::U16, s.iter().flat_map(|x| x.to_le_bytes()).collect()),
            Samples::I16(s) => (SampleType::I16, s.iter().flat_map(|x| x.to_le_bytes()).collect()),
            Samples::F32(s) => (SampleType::F32, s.iter().flat_map(|x| x.to_le_bytes()).collect()),
        };
        Ok(Self { dims, sample_type, spacing, bytes })
    }

    /// Bytes in one z slice.
    pub fn slice_bytes(&self) -> usize {
        usize::from(self.dims[0]) * usize::from(self.dims[1]) * self.sample_type.size()
    }
}

/// The commands that put `vol` on a board as `cfg` says, with consecutive
/// sequence numbers from `seq0`: `SetView` (if `cfg.view`), `BeginVolume`,
/// `SliceData` chunks of `cfg.chunk` bytes z slice by z slice, `EndVolume`.
/// What `send_volume` sends, and what the host's in-process board
/// ([`crate::scene`]) is fed: one way onto a board.
pub fn volume_messages<'v>(
    vol: &'v WireVolume,
    cfg: &SendConfig,
    levels: Levels,
    seq0: u16,
) -> impl Iterator<Item = Message<'v>> + 'v {
    let (chunk, slice_bytes) = (cfg.chunk.max(1), vol.slice_bytes().max(1));
    let seq = move |k: usize| seq0.wrapping_add(k as u16);
    let head = usize::from(cfg.view.is_some());
    let view = cfg.view.map(|v| {
        let [yaw, pitch, roll] = v.angles;
        Message::SetView {
            seq: seq(0),
            yaw,
            pitch,
            roll,
            fov_deg: v.fov_deg,
            spin_deg_per_s: v.spin_deg_per_s,
        }
    });
    let begin = Message::BeginVolume {
        seq: seq(head),
        dims: vol.dims,
        sample_type: vol.sample_type,
        spacing: vol.spacing,
        levels,
        axes: cfg.axes,
        every: cfg.every,
    };
    let data = vol
        .bytes
        .chunks(slice_bytes)
        .enumerate()
        .flat_map(move |(z, slice)| {
            slice.chunks(chunk).enumerate().map(move |(k, data)| (z as u16, (k * chunk) as u32, data))
        })
        .enumerate()
        .map(move |(k, (slice, offset, data))| Message::SliceData {
            seq: seq(head + 1 + k),
            slice,
            offset,
            data,
        });
    let chunks: usize = vol.bytes.chunks(slice_bytes).map(|s| s.len().div_ceil(chunk)).sum();
    let end = Message::EndVolume { seq: seq(head + 1 + chunks) };
    view.into_iter().chain(core::iter::once(begin)).chain(data).chain(core::iter::once(end))
}
