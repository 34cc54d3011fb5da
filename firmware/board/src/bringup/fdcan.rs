//! FDCAN1 in internal loopback: frames out and back, the acceptance filter, the bit timing
//! read back from NBTP, FIFO transmit mode.

use embassy_stm32::Peri;
use embassy_stm32::can::{CanConfigurator, Frame, OperatingMode};
use embassy_stm32::pac;
use embassy_stm32::pac::can::vals::Tfqm;
use embassy_stm32::peripherals::{FDCAN1, PA11, PA12};
use embassy_time::{Duration, with_timeout};

use hils_rig_core::can::{ID_COMMAND, ID_WHEEL_SPEED_12};
use hils_rig_core::can_timing::NominalBitTiming;

use super::verdict;
use crate::Irqs;
use crate::can_io;

const FRAMES: u8 = 4;

fn frame(id: u16, k: u8) -> Frame {
    let data = [k, 0x5A, 0xA5, k ^ 0xFF, 1, 2, 3, k];
    defmt::unwrap!(Frame::new_standard(id, &data).ok())
}

/// Internal loopback (RM0440 FDCAN test modes: TX held recessive, RX disconnected; own
/// frames are received through the acceptance filter): four command frames come back
/// intact, a wheel-speed-id frame is rejected by the filter.
pub async fn loopback(
    fdcan: Peri<'static, FDCAN1>,
    rx: Peri<'static, PA11>,
    tx: Peri<'static, PA12>,
) -> bool {
    let cfg = can_io::configure(CanConfigurator::new(fdcan, rx, tx, Irqs));
    let mut can = cfg.start(OperatingMode::InternalLoopbackMode);
    let t = can_io::bit_timing();
    let nbtp = can_io::nbtp_readback();
    let back = NominalBitTiming::from_nbtp(nbtp, t.kernel_hz);
    let fifo = pac::FDCAN1.txbc().read().tfqm() == Tfqm::FIFO;
    let mut intact = 0u8;
    for k in 0..FRAMES {
        let out = frame(ID_COMMAND, k);
        let _ = can.write(&out).await;
        if let Ok(Ok(env)) = with_timeout(Duration::from_millis(10), can.read()).await {
            let (f, _) = env.parts();
            if f.id() == out.id() && f.data() == out.data() {
                intact += 1;
            }
        }
    }
    let _ = can.write(&frame(ID_WHEEL_SPEED_12, 0)).await;
    let filtered = with_timeout(Duration::from_millis(10), can.read())
        .await
        .is_err();
    let pass = intact == FRAMES && filtered && nbtp == t.nbtp() && fifo;
    defmt::println!(
        "{=str} fdcan: loopback {=u8}/{=u8} frames back intact, id {=u16:#x} rejected by the filter {=bool}; NBTP {=u32:#010x} (computed {=u32:#010x}): {=u32} bit/s, {=u32} tq, sample point {=u32} permille, SJW {=u8}, tolerance {=u32} ppm; TX FIFO mode {=bool}",
        verdict(pass),
        intact,
        FRAMES,
        ID_WHEEL_SPEED_12,
        filtered,
        nbtp,
        t.nbtp(),
        back.bitrate(),
        back.tq_per_bit(),
        back.sample_point_permille(),
        back.sjw,
        back.tolerance().ppm(),
        fifo
    );
    pass
}
