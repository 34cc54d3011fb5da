//! FDCAN1 (PA11 RX, PA12 TX, AF9): classic CAN at 500 kbit/s with the bit timing computed
//! in `hils_rig_core::can_timing` from the 24 MHz HSE kernel clock, transmit FIFO mode,
//! one acceptance filter (the command id into RX FIFO 0, everything else rejected), stale
//! frames dropped and counted, bus-off counted in the FDCAN interrupt, recovery with backoff.

use core::num::{NonZeroU8, NonZeroU16};
use core::sync::atomic::Ordering;

use defmt::{info, unwrap, warn};
use embassy_stm32::can::config::{GlobalFilter, NominalBitTiming as EmbassyTiming, TxBufferMode};
use embassy_stm32::can::filter::{Action, FilterType, StandardFilter, StandardFilterSlot};
use embassy_stm32::can::{self, CanConfigurator, CanRx, CanTx, Frame, OperatingMode, Properties};
use embassy_stm32::interrupt::typelevel::{FDCAN1_IT0, Handler};
use embassy_stm32::pac;
use embassy_time::{Duration, Ticker, Timer, with_timeout};
use embedded_can::{Id, StandardId};
use hils_rig_core::bus::{BusAction, BusMode, BusMonitor, BusStatus};
use hils_rig_core::can::ID_COMMAND;
use hils_rig_core::can_timing::{BitTimingLimits, NominalBitTiming, nominal_bit_timing};
use hils_rig_core::can_tx::{QueuedFrame, TxSlots, frame_ticks, is_stale_behind};

use crate::clock::HSE_HZ;
use crate::shared::{
    BUS_CLEAR, BUS_OFF_IRQS, BUS_STATE, CAN_RX, CAN_TX, CAN_TX_DROPS, STEP_TICKS, THREAD_HEARTBEAT,
};

/// Counts bus-off entries as they happen (RM0440 FDCAN `IR.BO`: bus-off status changed,
/// routed to IT0 by embassy with `IE.BOE`): an episode shorter than the bus task's 10 ms
/// poll is counted too. Bound before embassy's IT0 handler, which acknowledges `IR.BO`.
pub struct BusOffCounter;

impl Handler<FDCAN1_IT0> for BusOffCounter {
    unsafe fn on_interrupt() {
        let regs = pac::FDCAN1;
        if regs.ir().read().bo() && regs.psr().read().bo() {
            BUS_OFF_IRQS.fetch_add(1, Ordering::Relaxed);
        }
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

/// The NBTP register as the controller holds it (for the start-up check and bring-up).
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

/// Starts FDCAN1 on the bus; checks the kernel clock and that the controller holds our
/// timing.
pub fn start(cfg: CanConfigurator<'static>) -> (CanTx<'static>, CanRx<'static>, Properties) {
    check_kernel_clock();
    let can = configure(cfg).start(OperatingMode::NormalOperationMode);
    let t = bit_timing();
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
    defmt::assert_eq!(
        nbtp_readback(),
        t.nbtp(),
        "FDCAN1 NBTP differs from the computed timing"
    );
    can.split()
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
                // FIFO mode: returns at once with a buffer free, and never aborts another.
                let _ = tx.write(&frame).await;
                slots.on_write(slot, id, tick);
                break;
            }
            Timer::after_micros(250).await;
        }
    }
}

/// Hands received `RIG_COMMAND` frames to the step (decoded and checked there). The
/// acceptance filter admits only the command id; the check here is a second line.
#[embassy_executor::task]
pub async fn can_rx_task(mut rx: CanRx<'static>) {
    loop {
        match rx.read().await {
            Ok(envelope) => {
                let (frame, _) = envelope.parts();
                if standard_id(&frame) != ID_COMMAND {
                    warn!(
                        "frame {=u16:#x} passed the acceptance filter",
                        standard_id(&frame)
                    );
                } else if CAN_RX.try_send(frame).is_err() {
                    warn!("command queue full: frame dropped");
                }
            }
            Err(e) => warn!("CAN receive error: {}", e),
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
                "CAN bus-off: restarting the controller (next try in {=u32} ms)",
                monitor.backoff_ms()
            );
            // Leaving INIT starts the bus-off recovery sequence again.
            pac::FDCAN1.cccr().modify(|w| w.set_init(false));
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
