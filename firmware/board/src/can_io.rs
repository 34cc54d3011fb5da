//! FDCAN1 (PA11 RX, PA12 TX, AF9): classic CAN at 500 kbit/s with the bit timing computed
//! in `hils_rig_core::can_timing` from the 24 MHz HSE kernel clock, started off the bus (in
//! internal loopback) and joined only after NBTP holds that timing (`fdcan::join_bus`),
//! transmit FIFO mode, one acceptance filter (the command id into RX FIFO 0, everything else
//! rejected), RX FIFO 0 drained in the FDCAN interrupt with lost frames (RF0L) counted, stale
//! frames dropped and counted, bus-off counted in the FDCAN interrupt, recovery with backoff
//! and the transmit FIFO flushed at each restart (`fdcan::restart_after_bus_off`).

use core::num::{NonZeroU8, NonZeroU16};
use core::sync::atomic::Ordering;

use defmt::{info, unwrap, warn};
use embassy_stm32::can::config::{GlobalFilter, NominalBitTiming as EmbassyTiming, TxBufferMode};
use embassy_stm32::can::filter::{Action, FilterType, StandardFilter, StandardFilterSlot};
use embassy_stm32::can::{self, CanConfigurator, CanTx, Frame, OperatingMode, Properties};
use embassy_stm32::interrupt::typelevel::{FDCAN1_IT0, Handler};
use embassy_stm32::pac;
use embassy_time::{Duration, Ticker, Timer, with_timeout};
use embedded_can::{Id, StandardId};
use hils_rig_core::bus::{BusAction, BusMode, BusMonitor, BusStatus};
use hils_rig_core::can::ID_COMMAND;
use hils_rig_core::can_timing::{BitTimingLimits, NominalBitTiming, nominal_bit_timing};
use hils_rig_core::can_tx::{QueuedFrame, TxSlots, frame_ticks, is_stale_behind};
use hils_rig_core::fdcan::{
    FdcanRegisters, RX_ELEMENT_BYTES, RX_FIFO_ELEMENTS, RX_FIFO0_OFFSET_BYTES, join_bus,
    restart_after_bus_off, rx_element,
};

use crate::clock::HSE_HZ;
use crate::shared::{
    BUS_CLEAR, BUS_OFF_IRQS, BUS_STATE, CAN_RX, CAN_TX, CAN_TX_DROPS, RX_LOST, STEP_TICKS,
    THREAD_HEARTBEAT,
};

/// FDCAN1's interrupt line 0 (P3, below the step), bound before embassy's handler: counts
/// bus-off entries as they happen (RM0440 FDCAN `IR.BO`, routed to IT0 by embassy with
/// `IE.BOE`: an episode shorter than the bus task's 10 ms poll is counted too; embassy's
/// handler acknowledges `IR.BO` after this one) and frames lost in RX FIFO 0 (`IR.RF0L`,
/// enabled by `start`). RF0L is a flag, not a count: losses between its setting and this
/// handler's clear count once, so `RxLost` is a lower bound (exact for a single loss and
/// for frames the step's queue could not take).
pub struct It0;

/// FDCAN1's interrupt line 0, bound after embassy's handler: drains RX FIFO 0 (3 elements)
/// into the step's command queue at once, instead of a thread-mode task that a busy
/// executor (a run's build, a telemetry record) delays past three frames of a setup burst;
/// a frame the queue cannot take is counted lost (`RIG_HEALTH` `RxLost`). After embassy's
/// handler, because that one clears `IR.RF0N`: a frame that arrives before that clear is
/// drained here, one that arrives after this drain sets `RF0N` again, which nobody clears,
/// and the interrupt comes back for it. The step's queue is a `StepChannel`: a P3 user is
/// within its ceiling's invariant.
pub struct It0Drain;

impl Handler<FDCAN1_IT0> for It0Drain {
    unsafe fn on_interrupt() {
        if RX_DRAIN.load(Ordering::Relaxed) {
            drain_rx_fifo0();
        }
    }
}

/// The application's receive path is on (`start`): the bring-up's loopback check reads
/// through embassy's driver instead, so the drain must leave its frames alone.
static RX_DRAIN: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(false);

impl Handler<FDCAN1_IT0> for It0 {
    unsafe fn on_interrupt() {
        let regs = pac::FDCAN1;
        let ir = regs.ir().read();
        if ir.bo() && regs.psr().read().bo() {
            BUS_OFF_IRQS.fetch_add(1, Ordering::Relaxed);
        }
        if ir.rfl(0) {
            regs.ir().write(|w| w.set_rfl(0, true));
            RX_LOST.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// Moves every frame in RX FIFO 0 to the step's command queue (RM0440 FDCAN: read the
/// element at the get index, then acknowledge it in RXF0A).
fn drain_rx_fifo0() {
    let regs = pac::FDCAN1;
    let ram = pac::FDCANRAM1.as_ptr() as *const u8;
    for _ in 0..RX_FIFO_ELEMENTS {
        let status = regs.rxfs(0).read();
        if status.ffl() == 0 {
            break;
        }
        let index = status.fgi();
        let at = RX_FIFO0_OFFSET_BYTES + index as usize * RX_ELEMENT_BYTES;
        // SAFETY: inside FDCAN1's message RAM (RX FIFO 0, element `index` < 3), word
        // aligned; the controller does not write an element before it is acknowledged.
        let word =
            |k: usize| unsafe { core::ptr::read_volatile(ram.add(at + 4 * k) as *const u32) };
        let (r0, r1, d0, d1) = (word(0), word(1), word(2), word(3));
        regs.rxfa(0).write(|w| w.set_fai(index));
        let frame = rx_element(r0, r1, [d0, d1])
            .filter(|e| e.id == ID_COMMAND)
            .and_then(|e| Frame::new_standard(e.id, &e.data[..e.len as usize]).ok());
        // Anything else passed a filter that admits only the command id: not a command.
        if let Some(f) = frame
            && CAN_RX.try_send(f).is_err()
        {
            RX_LOST.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// FDCAN1's registers for the host-tested sequences (`hils_rig_core::fdcan`).
struct Fdcan1;

impl FdcanRegisters for Fdcan1 {
    fn cccr(&self) -> u32 {
        pac::FDCAN1.cccr().read().0
    }
    fn set_cccr(&mut self, value: u32) {
        pac::FDCAN1.cccr().write_value(pac::can::regs::Cccr(value));
    }
    fn test(&self) -> u32 {
        pac::FDCAN1.test().read().0
    }
    fn set_test(&mut self, value: u32) {
        pac::FDCAN1.test().write_value(pac::can::regs::Test(value));
    }
    fn nbtp(&self) -> u32 {
        pac::FDCAN1.nbtp().read().0
    }
}

/// The rig's bus rate, bit/s.
pub const BITRATE: u32 = 500_000;
/// Transmit buffers of the controller (embassy's message RAM layout: TX_FIFO_MAX = 3).
const TX_BUFFERS: usize = 3;

/// The bit timing of the rig's bus (the computation is host-tested; an error here is a
/// build configuration error, caught on the first start).
pub fn bit_timing() -> NominalBitTiming {
    unwrap!(nominal_bit_timing(HSE_HZ, BITRATE, BitTimingLimits::FDCAN).ok())
}

/// Configures FDCAN1: our timing (embassy's `FdCanConfig::set_nominal_bit_timing`, the
/// supported way besides `set_bitrate`, which picks at most 17 quanta and SJW 1), FIFO
/// transmit (embassy `TxBufferMode::Fifo`: no pending frame is aborted for a
/// higher-priority one), no automatic bus-off recovery (the bus task restarts with backoff,
/// `hils_rig_core::bus`), and the acceptance filter. Returns
/// the configurator, to start in the mode the caller wants.
pub fn configure(mut cfg: CanConfigurator<'static>) -> CanConfigurator<'static> {
    let t = bit_timing();
    let nbtr = EmbassyTiming {
        prescaler: unwrap!(NonZeroU16::new(t.prescaler)),
        seg1: unwrap!(NonZeroU8::new(t.tseg1 as u8)),
        seg2: unwrap!(NonZeroU8::new(t.tseg2)),
        sync_jump_width: unwrap!(NonZeroU8::new(t.sjw)),
    };
    cfg.set_config(
        cfg.config()
            .set_nominal_bit_timing(nbtr)
            .set_tx_buffer_mode(TxBufferMode::Fifo)
            .set_automatic_bus_off_recovery(false)
            .set_global_filter(GlobalFilter::reject_all()),
    );
    cfg.properties().set_standard_filter(
        StandardFilterSlot::_0,
        StandardFilter {
            filter: FilterType::DedicatedSingle(unwrap!(StandardId::new(ID_COMMAND))),
            action: Action::StoreInFifo0,
        },
    );
    cfg
}

/// The NBTP register as the controller holds it (bring-up).
#[cfg(feature = "bringup")]
pub fn nbtp_readback() -> u32 {
    pac::FDCAN1.nbtp().read().0
}

/// The bit timing is computed for an FDCAN kernel clock of `HSE_HZ`: the kernel clock
/// embassy configured (`rcc::frequency`, from `clock::config`'s FDCANSEL) must be that,
/// else every quantum is off. A mismatch panics: the safe state, a defmt error, a reset.
pub fn check_kernel_clock() {
    let kernel_hz = embassy_stm32::rcc::frequency::<embassy_stm32::peripherals::FDCAN1>().0;
    if kernel_hz != HSE_HZ {
        defmt::panic!(
            "FDCAN1 kernel clock {=u32} Hz, but the bit timing is computed for {=u32} Hz",
            kernel_hz,
            HSE_HZ
        );
    }
}

/// Where the node goes after its start-up check.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Join {
    /// Onto the controller's bus (the rig).
    Bus,
    /// Stay in internal loopback, off the bus (the bring-up image's application run).
    Loopback,
}

/// Starts FDCAN1: checks the kernel clock, starts it in internal loopback (TX held
/// recessive, off the bus), and joins the bus (`join`) only once NBTP holds the computed
/// timing; a mismatch panics (safe state, reset, counted by the reset loop) before the node
/// has sent or acknowledged anything. RX FIFO 0 is drained by [`It0Drain`]; [`It0`]
/// counts lost frames (`IE.RF0LE`); the receive half of embassy's driver is not used.
pub fn start(cfg: CanConfigurator<'static>, join: Join) -> (CanTx<'static>, Properties) {
    check_kernel_clock();
    let can = configure(cfg).start(OperatingMode::InternalLoopbackMode);
    let t = bit_timing();
    // The receive path is on before the node joins: the first frame from the bus is drained
    // and a loss is counted (with the drain off, a frame arriving right after the join
    // would wait in the FIFO for the next one's interrupt).
    RX_DRAIN.store(true, Ordering::Relaxed);
    pac::FDCAN1.ie().modify(|w| w.set_rfle(0, true));
    if join == Join::Bus
        && let Err(e) = join_bus(&mut Fdcan1, t.nbtp())
    {
        defmt::panic!("FDCAN1 not started on the bus: {}", e);
    }
    let tol = t.tolerance();
    info!(
        "CAN {=u32} bit/s: kernel {=u32} Hz, prescaler {=u16}, {=u32} tq, sample point {=u32} permille, SJW {=u8}, tolerance {=u32} ppm, NBTP {=u32:#010x}",
        BITRATE,
        t.kernel_hz,
        t.prescaler,
        t.tq_per_bit(),
        t.sample_point_permille(),
        t.sjw,
        tol.ppm(),
        t.nbtp()
    );
    let (tx, _rx, props) = can.split();
    (tx, props)
}

fn standard_id(frame: &Frame) -> u16 {
    match frame.id() {
        Id::Standard(id) => id.as_raw(),
        Id::Extended(_) => u16::MAX,
    }
}

fn count_drops(n: u32) {
    if n > 0 {
        CAN_TX_DROPS.fetch_add(n, Ordering::Relaxed);
    }
}

/// Retires finished transmit buffers. Nothing is cancelled (FDCAN_TXBCR): the buffers run
/// in FIFO mode, for which the Bosch M_CAN manual says cancellation is not intended; stale
/// frames are dropped before they are written instead (`hils_rig_core::can_tx`).
fn service_buffers(slots: &mut TxSlots<TX_BUFFERS>) {
    let regs = pac::FDCAN1;
    let out = slots.retire(regs.txbrp().read().0, regs.txbto().read().0);
    count_drops(out.dropped);
}

/// Sends the frames the step queued, oldest first; a frame past its life (while the bus
/// is down, or behind others) is dropped and counted before it reaches the controller.
#[embassy_executor::task]
pub async fn can_tx_task(mut tx: CanTx<'static>) {
    let regs = pac::FDCAN1;
    let mut slots = TxSlots::<TX_BUFFERS>::new();
    loop {
        service_buffers(&mut slots);
        let next = if slots.occupied() == 0 {
            Some(CAN_TX.receive().await)
        } else {
            with_timeout(Duration::from_micros(250), CAN_TX.receive())
                .await
                .ok()
        };
        let Some(QueuedFrame { frame, tick }) = next else {
            continue;
        };
        let id = standard_id(&frame);
        // Wait for a free buffer, watching the frame's and the buffers' age.
        loop {
            service_buffers(&mut slots);
            let ahead = regs.txbrp().read().0.count_ones();
            let now = STEP_TICKS.load(Ordering::Relaxed);
            if is_stale_behind(id, tick, now, ahead, frame_ticks(BITRATE)) {
                count_drops(1);
                break;
            }
            // Nothing is written while bus-off: it would wait there and go out late.
            if !regs.psr().read().bo() && !regs.txfqs().read().tfqf() {
                let slot = regs.txfqs().read().tfqpi() as usize;
                // The put slot is free: a frame that was in it has ended, for good. Retire
                // it now (review C10: one that ended after the service above would
                // otherwise be overwritten by `on_write` and its outcome lost).
                service_buffers(&mut slots);
                // FIFO mode: returns at once with a buffer free, and never aborts another.
                let _ = tx.write(&frame).await;
                slots.on_write(slot, id, tick);
                break;
            }
            Timer::after_micros(250).await;
        }
    }
}

/// Polls the bus state every 10 ms: error passive, bus-off (and the interrupt's count),
/// restart with backoff, and the clear asked by `ClearFaults`; stamps thread mode's
/// heartbeat for the watchdog.
#[embassy_executor::task]
pub async fn bus_task(props: Properties) {
    let mut monitor = BusMonitor::new();
    let mut ticker = Ticker::every(Duration::from_millis(10));
    let mut drops_logged = 0;
    let mut rx_lost_logged = 0;
    loop {
        ticker.next().await;
        // Thread mode is alive: the step keeps feeding the watchdog.
        THREAD_HEARTBEAT.store(STEP_TICKS.load(Ordering::Relaxed), Ordering::Relaxed);
        let mode = match props.bus_error_mode() {
            can::enums::BusErrorMode::ErrorActive => BusMode::ErrorActive,
            can::enums::BusErrorMode::ErrorPassive => BusMode::ErrorPassive,
            can::enums::BusErrorMode::BusOff => BusMode::BusOff,
        };
        let status = BusStatus {
            mode,
            tx_errors: props.tx_error_count(),
            rx_errors: props.rx_error_count(),
        };
        let now_ms = embassy_time::Instant::now().as_millis() as u32;
        monitor.note_irq_bus_offs(BUS_OFF_IRQS.load(Ordering::Relaxed));
        let (event, action) = monitor.poll(status, now_ms);
        if BUS_CLEAR.swap(false, Ordering::Relaxed) {
            // Refused while bus-off: the flag stays until the controller is back.
            monitor.clear();
        }
        if let Some(e) = event {
            warn!(
                "CAN bus: {} (TEC {}, REC {})",
                e, status.tx_errors, status.rx_errors
            );
        }
        if action == BusAction::Restart {
            warn!(
                "CAN bus-off: restarting the controller with its transmit FIFO flushed (next try in {=u32} ms)",
                monitor.backoff_ms()
            );
            // CCE flushes the frames queued before the bus-off; leaving INIT starts the
            // bus-off recovery sequence again.
            if let Err(e) = restart_after_bus_off(&mut Fdcan1) {
                warn!("CAN restart: {}", e);
            }
        }
        let lost = RX_LOST.load(Ordering::Relaxed);
        if lost != rx_lost_logged {
            warn!("CAN: {=u32} command frames lost in reception so far", lost);
            rx_lost_logged = lost;
        }
        let bits = (mode == BusMode::ErrorPassive) as u32
            | ((monitor.bus_off_seen as u32) << 1)
            | (monitor.bus_off_count.min(0x00FF_FFFF) << 8);
        BUS_STATE.store(bits, Ordering::Relaxed);
        let drops = CAN_TX_DROPS.load(Ordering::Relaxed);
        if drops != drops_logged {
            warn!("CAN: {=u32} frames dropped stale so far", drops);
            drops_logged = drops;
        }
    }
}
