//! The link between `hils rig` and the board: send and receive classic CAN frames with
//! timeouts, whatever carries them (the in-process simulated board, [`super::sim`], or a
//! SocketCAN interface, [`super::socketcan`]).
//!
//! Frames are `hils_rig_core::can::ClassicFrame` (an `embedded_can::Frame`), so every encoder
//! and decoder of `hils.dbc` in `rig-core` works on them unchanged.

use hils_rig_core::can::ClassicFrame;
use hils_rig_core::hw::TelemetryEvent;

/// A frame as received, stamped on the transport's clock (s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Received {
    pub frame: ClassicFrame,
    pub t_s: f64,
}

/// A telemetry event of the board's probe capture (defmt), stamped on the transport's clock.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeEvent {
    pub t_s: f64,
    pub event: TelemetryEvent,
}

/// Why the transport cannot carry frames.
#[derive(Clone, Debug, PartialEq)]
pub enum TransportError {
    /// The host's CAN controller is bus-off (an error frame or the controller said so).
    BusOff,
    /// An error from the operating system or the adapter.
    Io(String),
}

impl std::fmt::Display for TransportError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TransportError::BusOff => f.write_str("the CAN controller is bus-off"),
            TransportError::Io(e) => write!(f, "CAN interface error: {e}"),
        }
    }
}

impl std::error::Error for TransportError {}

/// Sends and receives CAN frames.
pub trait Transport {
    /// Sends a frame (returns once it is queued for transmission).
    fn send(&mut self, frame: &ClassicFrame) -> Result<(), TransportError>;

    /// The next frame, waiting at most `timeout_s` on the transport's clock; `Ok(None)` when
    /// none came in time.
    fn receive(&mut self, timeout_s: f64) -> Result<Option<Received>, TransportError>;

    /// The transport's clock, s (board time for the simulation, monotonic host time for a
    /// CAN interface).
    fn now_s(&self) -> f64;

    /// Telemetry the probe captured since the last call (empty without a probe).
    fn take_probe(&mut self) -> Vec<ProbeEvent> {
        Vec::new()
    }

    /// What the transport is, for logs and reports (`sim`, `can0`).
    fn describe(&self) -> String;
}
