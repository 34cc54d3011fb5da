//! Clock tree and CCM code checks.

use embassy_stm32::pac;
use embassy_stm32::pac::rcc::vals::{Hpre, Pllsrc, Sw};
use hils_rig_core::bringup::ClockReadback;

use super::verdict;
use crate::ccm;

fn ahb_divider(h: Hpre) -> u32 {
    match h {
        Hpre::DIV1 => 1,
        Hpre::DIV2 => 2,
        Hpre::DIV4 => 4,
        Hpre::DIV8 => 8,
        Hpre::DIV16 => 16,
        Hpre::DIV64 => 64,
        Hpre::DIV128 => 128,
        Hpre::DIV256 => 256,
        Hpre::DIV512 => 512,
        _ => 0,
    }
}

/// Reads RCC, PWR and FLASH back: SYSCLK from the PLL on HSE, 170 MHz, boost, 4 wait
/// states, prefetch and caches on, clock security on.
pub fn clock_tree() -> bool {
    let cr = pac::RCC.cr().read();
    let pll = pac::RCC.pllcfgr().read();
    let acr = pac::FLASH.acr().read();
    let rb = ClockReadback {
        hse_ready: cr.hserdy(),
        pll_ready: cr.pllrdy(),
        sysclk_is_pll: pac::RCC.cfgr().read().sws() == Sw::PLL1_R,
        pll_from_hse: pll.pllsrc() == Pllsrc::HSE,
        pll_m: pll.pllm().to_bits() as u32 + 1,
        pll_n: pll.plln().to_bits() as u32,
        pll_r: 2 * (pll.pllr().to_bits() as u32 + 1),
        ahb_div: ahb_divider(pac::RCC.cfgr().read().hpre()),
        flash_ws: acr.latency().to_bits(),
        boost: !pac::PWR.cr5().read().r1mode(),
    };
    let tree = rb.check();
    let accel = acr.prften() && acr.icen() && acr.dcen();
    let pass = tree.is_ok() && accel && cr.csson();
    defmt::println!(
        "{=str} clock: SYSCLK {=u32} Hz = HSE {=u32} Hz / {=u32} x {=u32} / {=u32}; HSE ready {=bool}, PLL ready {=bool}, boost {=bool}, flash {=u8} WS, prefetch+caches {=bool}, CSS {=bool}",
        verdict(pass),
        rb.sysclk_hz(),
        hils_rig_core::bringup::HSE_HZ,
        rb.pll_m,
        rb.pll_n,
        rb.pll_r,
        rb.hse_ready,
        rb.pll_ready,
        rb.boost,
        rb.flash_ws,
        accel,
        cr.csson()
    );
    if let Err(e) = tree {
        defmt::println!("  clock fault: {}", e);
    }
    pass
}

/// The step's code in CCM SRAM equals its flash image and its pages are write-protected.
pub fn ccm_code() -> bool {
    let (at, len) = ccm::code_span();
    let same = ccm::matches_load_image();
    let pages = ccm::code_pages();
    let protected = pac::SYSCFG.swpr().read().0 & pages == pages;
    let pass = len > 0 && same && protected;
    defmt::println!(
        "{=str} ccm: {=u32} B of step code at {=u32:#010x} equal to its flash image at {=u32:#010x}: {=bool}; pages {=u32:#010x} write-protected: {=bool}",
        verdict(pass),
        len,
        at,
        ccm::load_address(),
        same,
        pages,
        protected
    );
    pass
}
