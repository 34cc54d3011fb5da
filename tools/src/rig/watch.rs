//! `hils rig watch`: a live text view of the board from its frames (wheel speeds, state,
//! faults, step timing, bus errors), redrawn at the status rate (every `RIG_STATUS`, 10 ms)
//! on a terminal; when the output is not a terminal, one block per `--every-s` of board
//! time (a log or a captured text).

use std::fmt::Write as _;
use std::io::{IsTerminal, Write};

use hils_rig_core::rig::Faults;

use super::monitor::{BoardView, Seen};
use super::monitor::{mode_name, result_name, sensor_fault_name, state_name};

/// The names of the fault bits set (sensor channels as `sensorN`, the other flags of
/// `RIG_STATUS` by their [`Faults`] name in kebab case: `CAN_BUS_OFF` -> `can-bus-off`).
pub fn fault_names(faults: u16) -> Vec<String> {
    let f = faults as u32;
    let mut names: Vec<String> = (0..4)
        .filter(|j| f & (1 << j) != 0)
        .map(|j| format!("sensor{}", j + 1))
        .collect();
    let flags = Faults::from_bits_truncate(f).difference(Faults::SENSOR);
    names.extend(
        flags
            .iter_names()
            .map(|(name, _)| name.to_lowercase().replace('_', "-")),
    );
    names
}

/// The view's text at board time `t_s`.
pub fn render(board: &BoardView, source: &str, t_s: f64) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "hils rig watch  {source}  t = {t_s:.2} s");
    match board.status() {
        Some(st) => {
            let _ = writeln!(
                s,
                "state {:<9} mode {:<9} last command {}",
                state_name(st.state),
                mode_name(st.mode),
                result_name(st.command_result)
            );
            let _ = writeln!(
                s,
                "vehicle {:7.2} km/h   deceleration {:6.3} m/s2",
                st.vehicle_speed_kmh, st.deceleration_mps2
            );
            let names = fault_names(st.faults);
            let _ = writeln!(
                s,
                "faults 0x{:04x} {}",
                st.faults,
                if names.is_empty() {
                    "none".to_string()
                } else {
                    names.join(" ")
                }
            );
        }
        None => s.push_str("no status frame yet\n"),
    }
    s.push_str("wheel km/h");
    match board.wheel_speed {
        Some((_, w)) => {
            for (j, v) in w.speeds_kmh.iter().enumerate() {
                let _ = match v {
                    Some(v) => write!(s, "   {}: {v:7.2}", j + 1),
                    None => write!(s, "   {}:     n/a", j + 1),
                };
            }
        }
        None => s.push_str("   no wheel-speed frame yet"),
    }
    s.push('\n');
    match board.diag {
        Some((_, d)) => {
            let sensors: Vec<String> = d
                .sensor_faults
                .iter()
                .enumerate()
                .map(|(j, f)| match f {
                    Some(f) => format!("{}:{}", j + 1, sensor_fault_name(*f)),
                    None => format!("{}:ok", j + 1),
                })
                .collect();
            let _ = writeln!(
                s,
                "step max {:6.2} us  mean {:6.2} us  overruns {}  sensors {}",
                d.step_max_us,
                d.step_mean_us,
                d.overruns,
                sensors.join(" ")
            );
            let _ = write!(s, "bus: board bus-off count {}", d.bus_off_count);
        }
        None => s.push_str("bus: no diagnostic frame yet"),
    }
    if let Some((_, h)) = board.health {
        let arming = match h.disarmed {
            None => "armed (outputs to the controller live in rig-mode runs)".to_string(),
            Some(why) => format!("disarmed ({})", disarm_name(why)),
        };
        let _ = write!(
            s,
            "\n{arming}  stack peak {} of {} B  rx lost at least {}  adc restarts {}  fault resets {}",
            h.stack_peak_bytes, h.stack_size_bytes, h.rx_lost, h.adc_restarts, h.fault_resets
        );
    }
    let c = &board.counts;
    let _ = writeln!(
        s,
        "  frames wheel {} status {} diag {}  lost wheel {} status {}  bad {}  other {}",
        c.wheel_speed,
        c.status,
        c.diag,
        board.wheel_alive.lost,
        board.status_alive.lost,
        c.bad,
        c.other
    );
    s
}

/// Draws the view as frames come.
pub struct Watcher<W: Write> {
    out: W,
    tty: bool,
    every_s: f64,
    next_s: Option<f64>,
    source: String,
}

impl Watcher<std::io::Stdout> {
    /// On standard output (redrawn in place on a terminal).
    pub fn stdout(source: &str, every_s: f64) -> Self {
        let out = std::io::stdout();
        let tty = out.is_terminal();
        Self::new(out, tty, source, every_s)
    }
}

impl<W: Write> Watcher<W> {
    pub fn new(out: W, tty: bool, source: &str, every_s: f64) -> Self {
        Self {
            out,
            tty,
            every_s,
            next_s: None,
            source: source.into(),
        }
    }

    /// Called for every frame: draws on status frames (all of them on a terminal).
    pub fn frame(&mut self, board: &BoardView, seen: &Seen) {
        let Seen::Status(_) = seen else { return };
        let t = board.status.map_or(0.0, |(t, _)| t);
        if !self.tty {
            if self.next_s.is_some_and(|n| t < n) {
                return;
            }
            self.next_s = Some(t + self.every_s);
        }
        self.draw(board, t);
    }

    /// Draws now.
    pub fn draw(&mut self, board: &BoardView, t_s: f64) {
        let text = render(board, &self.source, t_s);
        let _ = if self.tty {
            write!(self.out, "\x1b[H\x1b[2J{text}")
        } else {
            writeln!(self.out, "{text}")
        };
        let _ = self.out.flush();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fault_names_are_the_status_flags_in_kebab_case() {
        assert_eq!(
            fault_names(0xFFFF).join(" "),
            "sensor1 sensor2 sensor3 sensor4 overrun can-error-passive can-bus-off plant-input \
             plant-numeric speed-saturated command-rejected telemetry-dropped fault-injected \
             adc-stale can-tx-dropped missed-ticks"
        );
        assert_eq!(fault_names(0b10 | 0x0040), ["sensor2", "can-bus-off"]);
        assert!(fault_names(0).is_empty());
    }
}

/// Why the board is disarmed, in words.
pub fn disarm_name(why: hils_rig_core::arming::Disarm) -> &'static str {
    use hils_rig_core::arming::Disarm;
    match why {
        Disarm::Reset => "since reset",
        Disarm::Command => "by command",
        Disarm::Fault => "by a fault",
        Disarm::Stop => "by stop",
        Disarm::SelfTest => "by a self-test start",
    }
}
