//! ADC1 on VREFINT and the temperature sensor, with the factory calibration values.

use embassy_stm32::Peri;
use embassy_stm32::adc::{Adc, AdcConfig, SampleTime};
use embassy_stm32::peripherals::ADC1;
use embassy_time::Timer;
use hils_rig_core::bringup::{
    AdcFactoryCal, DIE_TEMPERATURE_RANGE_DEGC, VDDA_RANGE_MV, die_temperature_c, vdda_mv,
};

use super::verdict;

/// Factory calibration addresses (ST stm32g4xx_ll_adc.h: VREFINT_CAL_ADDR,
/// TEMPSENSOR_CAL1_ADDR, TEMPSENSOR_CAL2_ADDR; VREFINT_CAL is also stm32-metapac's
/// `VREFINTCAL` for the G474).
const VREFINT_CAL: u32 = 0x1FFF_75AA;
const TS_CAL1: u32 = 0x1FFF_75A8;
const TS_CAL2: u32 = 0x1FFF_75CA;
const SAMPLES: u32 = 16;

fn read_cal(addr: u32) -> u16 {
    // SAFETY: system-memory words of the STM32G4, always readable.
    unsafe { core::ptr::read_volatile(addr as *const u16) }
}

/// VDDA from VREFINT within 3.3 V +-5 %, the die temperature believable, the calibration
/// values plausible. Sampling 640.5 ADC cycles (15 us at 42.5 MHz): above the datasheet
/// minimum for both internal channels (a few us).
pub async fn vrefint_and_temperature(adc1: Peri<'static, ADC1>) -> bool {
    let mut adc = Adc::new(adc1, AdcConfig::default());
    let mut vrefint = adc.enable_vrefint();
    let mut temp = adc.enable_temperature();
    // Sensor start-up (ST LL: 120 us for the temperature sensor, 12 us for VREFINT).
    Timer::after_millis(1).await;
    let (mut v, mut ts) = (0u32, 0u32);
    for _ in 0..SAMPLES {
        v += adc.blocking_read(&mut vrefint, SampleTime::CYCLES640_5) as u32;
        ts += adc.blocking_read(&mut temp, SampleTime::CYCLES640_5) as u32;
    }
    let (v, ts) = ((v / SAMPLES) as u16, (ts / SAMPLES) as u16);
    let cal = AdcFactoryCal {
        vrefint_cal: read_cal(VREFINT_CAL),
        ts_cal1: read_cal(TS_CAL1),
        ts_cal2: read_cal(TS_CAL2),
    };
    let vdda = vdda_mv(&cal, v);
    let degc = die_temperature_c(&cal, ts, vdda);
    let pass = cal.plausible()
        && (VDDA_RANGE_MV.0..=VDDA_RANGE_MV.1).contains(&vdda)
        && (DIE_TEMPERATURE_RANGE_DEGC.0..=DIE_TEMPERATURE_RANGE_DEGC.1).contains(&degc);
    defmt::println!(
        "{=str} adc: VREFINT {=u16} counts (VREFINT_CAL {=u16}) -> VDDA {=u32} mV; temperature sensor {=u16} counts (TS_CAL1 {=u16}, TS_CAL2 {=u16}) -> {=f32} degC",
        verdict(pass),
        v,
        cal.vrefint_cal,
        vdda,
        ts,
        cal.ts_cal1,
        cal.ts_cal2,
        degc
    );
    pass
}
