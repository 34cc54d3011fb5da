//! Transmit freshness against a model of the board's transmit path: the step's schedule
//! (wheel speeds every 1 ms, status every 10 ms, diagnostics every 100 ms) into a 32-deep
//! queue, the transmit task's rules, the controller's 3-buffer FIFO and a 500 kbit/s bus
//! (~0.25 ms a frame) that goes away for a while. Checked: nothing older than its life
//! goes out after a bus-off (the task writes nothing into the controller while bus-off),
//! at most the three frames in the controller go out late after an outage without
//! bus-off (no cancellation in FIFO mode), and every frame is accounted for (sent,
//! dropped and counted, or still in flight).

use std::collections::VecDeque;

use hils_rig_core::can::{ID_DIAG, ID_STATUS, ID_WHEEL_SPEED_12, ID_WHEEL_SPEED_34};
use hils_rig_core::can_tx::{TxSlots, frame_ticks, is_stale, is_stale_behind, max_age_ticks};

const QUEUE: usize = 32;
const HW_SLOTS: usize = 3;
/// Ticks (0.1 ms) one frame occupies the bus at 500 kbit/s (~125 bits with stuffing).
const FRAME_TICKS: u32 = 3;

#[derive(Default)]
struct Counts {
    produced: u32,
    queue_full: u32,
    stale_in_queue: u32,
    sent: u32,
    ended_unsent: u32,
}

struct Model {
    queue: VecDeque<(u16, u32)>,
    /// Controller buffers: (slot, id, tick), in FIFO order.
    hw: VecDeque<(usize, u16, u32)>,
    slots: TxSlots<HW_SLOTS>,
    /// Transmission in progress: slot and the tick it ends.
    on_bus: Option<(usize, u16, u32, u32)>,
    pending: u32,
    tx_occurred: u32,
    c: Counts,
    /// Age (ticks) of each frame when it started on the bus, by id.
    sent_ages: Vec<(u32, u16, u32)>,
}

impl Model {
    fn new() -> Self {
        Self {
            queue: VecDeque::new(),
            hw: VecDeque::new(),
            slots: TxSlots::new(),
            on_bus: None,
            pending: 0,
            tx_occurred: 0,
            c: Counts::default(),
            sent_ages: vec![],
        }
    }

    /// The step's schedule (rig.rs): both wheel-speed frames at tick % 10 == 0, status at % 100 == 5,
    /// diagnostics at % 1000 == 50.
    fn step(&mut self, tick: u32) {
        for (id, due) in [
            (ID_WHEEL_SPEED_12, tick % 10 == 0),
            (ID_WHEEL_SPEED_34, tick % 10 == 0),
            (ID_STATUS, tick % 100 == 5),
            (ID_DIAG, tick % 1000 == 50),
        ] {
            if due {
                self.c.produced += 1;
                if self.queue.len() < QUEUE {
                    self.queue.push_back((id, tick));
                } else {
                    self.c.queue_full += 1;
                }
            }
        }
    }

    /// One pass of the board's transmit task (`bus_off`: FDCAN_PSR.BO).
    fn tx_task(&mut self, now: u32, bus_off: bool) {
        let out = self.slots.retire(self.pending, self.tx_occurred);
        self.c.sent += out.sent;
        self.c.ended_unsent += out.dropped;
        // Stale frames are dropped in the queue whether or not they can be written.
        while let Some(&(id, tick)) = self.queue.front() {
            if !is_stale(id, tick, now) {
                break;
            }
            self.queue.pop_front();
            self.c.stale_in_queue += 1;
        }
        while !bus_off && self.hw.len() < HW_SLOTS {
            let Some((id, tick)) = self.queue.pop_front() else {
                break;
            };
            let ahead = self.pending.count_ones();
            if is_stale_behind(id, tick, now, ahead, frame_ticks(500_000)) {
                self.c.stale_in_queue += 1;
                continue;
            }
            let slot = (0..HW_SLOTS)
                .find(|s| self.pending & (1 << s) == 0 && self.slots.occupied() & (1 << s) == 0);
            let Some(slot) = slot else {
                self.queue.push_front((id, tick));
                break;
            };
            self.hw.push_back((slot, id, tick));
            self.pending |= 1 << slot;
            self.tx_occurred &= !(1 << slot);
            self.slots.on_write(slot, id, tick);
        }
    }

    fn bus(&mut self, now: u32, up: bool) {
        if let Some((slot, _, _, end)) = self.on_bus {
            // Wrapping tick clock: `end` reached when now - end is not negative.
            if now.wrapping_sub(end) as i32 >= 0 {
                self.on_bus = None;
                if up {
                    self.hw.retain(|e| e.0 != slot);
                    self.pending &= !(1 << slot);
                    self.tx_occurred |= 1 << slot;
                }
            }
        }
        if up && self.on_bus.is_none() {
            if let Some(&(slot, id, tick)) = self.hw.front() {
                self.sent_ages.push((now, id, now.wrapping_sub(tick)));
                self.on_bus = Some((slot, id, tick, now.wrapping_add(FRAME_TICKS)));
            }
        }
    }

    fn in_flight(&self) -> u32 {
        (self.queue.len() + self.hw.len()) as u32
    }
}

/// `down`: ticks without the bus; `bus_off`: the controller reports it (else: no
/// acknowledge, error passive, the controller keeps retrying).
fn run(start: u32, ticks: u32, down: std::ops::Range<u32>, bus_off: bool) -> Model {
    let mut m = Model::new();
    for k in 0..ticks {
        let now = start.wrapping_add(k);
        let up = !down.contains(&k);
        m.step(now);
        m.tx_task(now, bus_off && !up);
        m.bus(now, up);
    }
    m
}

fn accounted(m: &Model) {
    let c = &m.c;
    // Finished on the bus since the task's last pass: not yet retired.
    let unretired = (m.slots.occupied() & !m.pending).count_ones();
    assert_eq!(
        c.produced,
        c.sent + c.queue_full + c.stale_in_queue + c.ended_unsent + m.in_flight() + unretired,
        "every frame sent, dropped and counted, or in flight"
    );
}

#[test]
fn a_frame_is_three_ticks_at_500_kbit() {
    assert_eq!(frame_ticks(500_000), FRAME_TICKS);
    assert_eq!(frame_ticks(1_000_000), 2);
    assert_eq!(frame_ticks(125_000), 11);
}

#[test]
fn a_healthy_bus_sends_everything_fresh() {
    let m = run(0, 20_000, 0..0, false);
    assert_eq!(m.c.queue_full + m.c.stale_in_queue + m.c.ended_unsent, 0);
    assert!(
        m.sent_ages
            .iter()
            .all(|&(_, id, age)| age <= max_age_ticks(id))
    );
    accounted(&m);
}

#[test]
fn after_an_outage_only_the_controllers_frames_go_late() {
    // Bus away 35 ms (the burst: the 32-deep queue full of old wheel speeds), as
    // bus-off or as no acknowledge: the controller keeps the (up to) three frames it held
    // (no cancellation in FIFO mode); everything behind them is dropped in the queue.
    for bus_off in [true, false] {
        for start in [0u32, 7, u32::MAX - 150] {
            let down = 200..550;
            let m = run(start, 3_000, down.clone(), bus_off);
            assert!(m.c.stale_in_queue > 30, "the outage's frames are dropped");
            let late: Vec<_> = m
                .sent_ages
                .iter()
                .filter(|&&(_, id, age)| age > max_age_ticks(id))
                .collect();
            assert!(late.len() <= HW_SLOTS, "late: {late:?}");
            for &&(at, _, _) in &late {
                let k = at.wrapping_sub(start);
                assert!(
                    (down.end..down.end + (HW_SLOTS as u32) * FRAME_TICKS).contains(&k),
                    "late only as the first frames at the return: {late:?}"
                );
            }
            // The first wheel-speed frame after those is at most 1 ms old.
            let first = m
                .sent_ages
                .iter()
                .find(|&&(at, id, age)| {
                    at.wrapping_sub(start) >= down.end && id == ID_WHEEL_SPEED_12 && age < 100
                })
                .unwrap();
            assert!(first.2 <= 10);
            accounted(&m);
        }
    }
}
