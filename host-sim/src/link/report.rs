//! What the board said about itself, and what a transfer did.

use isoscope_core::wire::{DeviceState, NackCode};

/// What the board said about itself.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BoardInfo {
    /// Its firmware version.
    pub firmware: [u8; 3],
    /// The largest slice in bytes of `u8` samples.
    pub max_slice_samples: u32,
    /// Sample types it takes (bit set).
    pub sample_types: u8,
    /// Points its display list holds.
    pub display_points: u32,
    /// Hellos sent before it answered (1 on a clean line; each more is a
    /// timeout and a retransmission).
    pub hellos: u32,
}

/// What a transfer did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SendReport {
    /// The board.
    pub board: BoardInfo,
    /// Sample bytes delivered.
    pub payload_bytes: u64,
    /// Bytes written to the line (all frames, retransmissions included).
    pub wire_bytes: u64,
    /// Frames in the transfer.
    pub frames: u64,
    /// Frames sent again.
    pub retransmitted: u64,
    /// Nacks received, by code.
    pub nacks: Vec<(NackCode, u32)>,
    /// Timeouts (no acknowledgement in time).
    pub timeouts: u32,
    /// From the first frame of the volume to the last acknowledgement.
    pub seconds: f64,
    /// From writing `EndVolume` (right after the last slice) to its
    /// acknowledgement.
    pub end_ack_seconds: f64,
    /// From writing `EndVolume` to the board's status report, which it sends
    /// once the new picture is on screen (contoured, stitched, ordered).
    pub picture_seconds: Option<f64>,
    /// The board's status after the volume.
    pub status: Option<(DeviceState, u32, u16)>,
}

impl SendReport {
    /// Payload bytes per second.
    pub fn throughput(&self) -> f64 {
        self.payload_bytes as f64 / self.seconds.max(1e-9)
    }

    /// Payload throughput as a share of the line rate (8N1: 10 bits a byte).
    pub fn efficiency(&self, baud: u32) -> f64 {
        self.throughput() * 10.0 / f64::from(baud.max(1))
    }

    /// The report as `key=value` lines.
    pub fn report(&self, baud: u32) -> String {
        let mut s = String::new();
        let mut kv = |k: &str, v: String| s.push_str(&format!("{k}={v}\n"));
        kv("payload_bytes", self.payload_bytes.to_string());
        kv("wire_bytes", self.wire_bytes.to_string());
        kv("frames", self.frames.to_string());
        kv("retransmitted_frames", self.retransmitted.to_string());
        kv("timeouts", self.timeouts.to_string());
        let nacks: Vec<String> = self.nacks.iter().map(|(c, n)| format!("{c:?}:{n}")).collect();
        kv("nacks", if nacks.is_empty() { "0".into() } else { nacks.join(",") });
        kv("seconds", format!("{:.3}", self.seconds));
        kv("throughput_bytes_per_s", format!("{:.0}", self.throughput()));
        kv("line_rate_bytes_per_s", format!("{:.0}", f64::from(baud) / 10.0));
        kv("payload_efficiency", format!("{:.4}", self.efficiency(baud)));
        kv("end_to_ack_ms", format!("{:.1}", self.end_ack_seconds * 1e3));
        if let Some(p) = self.picture_seconds {
            kv("last_slice_to_picture_ms", format!("{:.1}", p * 1e3));
        }
        if let Some((state, points, centi_hz)) = self.status {
            kv("board_state", format!("{state:?}"));
            kv("board_points", points.to_string());
            kv("board_refresh_hz", format!("{:.2}", f64::from(centi_hz) / 100.0));
        }
        s
    }
}
