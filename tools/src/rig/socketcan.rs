//! The SocketCAN transport (Linux only): a thin adapter of the `socketcan` crate's
//! `CanSocket` to [`Transport`]. Error frames are enabled; a bus-off error frame is
//! [`TransportError::BusOff`], other error frames (error passive, no ACK, bus errors) are
//! skipped by the transport and counted in [`SocketCan::error_frames`].
//!
//! Not run in this project's tests: the kernel here has no `vcan` module, so this compiles
//! but needs a CAN adapter (`ip link set can0 up type can bitrate 500000`) to be verified.

use anyhow::Result;

use super::transport::Transport;

/// Opens a SocketCAN interface (`can0`).
#[cfg(target_os = "linux")]
pub fn open(interface: &str) -> Result<Box<dyn Transport>> {
    Ok(Box::new(linux::SocketCan::open(interface)?))
}

/// SocketCAN exists only on Linux.
#[cfg(not(target_os = "linux"))]
pub fn open(interface: &str) -> Result<Box<dyn Transport>> {
    anyhow::bail!("{interface}: SocketCAN needs Linux; use `--interface sim` here")
}

#[cfg(target_os = "linux")]
pub use linux::SocketCan;

#[cfg(target_os = "linux")]
mod linux {
    use std::time::{Duration, Instant};

    use anyhow::{Context, Result};
    use hils_rig_core::can::ClassicFrame;
    use socketcan::errors::ErrorCause;
    use socketcan::{CanFrame, CanSocket, EmbeddedFrame, Socket, SocketOptions};

    use super::super::transport::{Received, Transport, TransportError};

    /// A SocketCAN interface.
    pub struct SocketCan {
        socket: CanSocket,
        interface: String,
        epoch: Instant,
        /// Error frames other than bus-off seen.
        pub error_frames: u64,
    }

    impl SocketCan {
        pub fn open(interface: &str) -> Result<Self> {
            let socket = CanSocket::open(interface).with_context(|| {
                format!("cannot open CAN interface `{interface}` (is it up? `ip link set {interface} up type can bitrate 500000`)")
            })?;
            socket
                .set_error_filter_accept_all()
                .with_context(|| format!("{interface}: cannot enable error frames"))?;
            Ok(Self {
                socket,
                interface: interface.to_string(),
                epoch: Instant::now(),
                error_frames: 0,
            })
        }
    }

    fn io(e: std::io::Error) -> TransportError {
        TransportError::Io(e.to_string())
    }

    impl Transport for SocketCan {
        fn send(&mut self, frame: &ClassicFrame) -> Result<(), TransportError> {
            let f = CanFrame::new(frame.id, EmbeddedFrame::data(frame)).ok_or_else(|| {
                TransportError::Io("frame does not fit a classic CAN frame".into())
            })?;
            self.socket.write_frame(&f).map_err(io)
        }

        fn receive(&mut self, timeout_s: f64) -> Result<Option<Received>, TransportError> {
            let deadline = Instant::now() + Duration::from_secs_f64(timeout_s.clamp(0.0, 3600.0));
            loop {
                let left = deadline.saturating_duration_since(Instant::now());
                let frame = match self.socket.read_frame_timeout(left) {
                    Ok(f) => f,
                    Err(e) if e.kind() == std::io::ErrorKind::TimedOut => return Ok(None),
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return Ok(None),
                    Err(e) => return Err(io(e)),
                };
                let t_s = self.now_s();
                let classic = match frame {
                    CanFrame::Error(e) => {
                        if e.into_error().causes().any(|c| *c == ErrorCause::BusOff) {
                            return Err(TransportError::BusOff);
                        }
                        self.error_frames += 1;
                        continue;
                    }
                    CanFrame::Remote(_) => continue,
                    CanFrame::Data(d) => <ClassicFrame as EmbeddedFrame>::new(d.id(), d.data()),
                };
                if let Some(frame) = classic {
                    return Ok(Some(Received { frame, t_s }));
                }
            }
        }

        fn now_s(&self) -> f64 {
            self.epoch.elapsed().as_secs_f64()
        }

        fn describe(&self) -> String {
            format!("SocketCAN {}", self.interface)
        }
    }
}
