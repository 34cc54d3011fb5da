//! The controller's WSP valves as the board reads them: each wheelset's dump (vent) and hold
//! valve coil signals on digital inputs, sampled at the start of every step and debounced.
//!
//! **Interface stage** (docs/rig.md, "Controller I/O"): each coil (24 V or 110 V) drives an
//! optocoupler LED through a series resistor and a reverse diode; the transistor pulls the
//! input low while the coil is energised, a pull-up holds it high otherwise, so a coil signal
//! is *active low* at the pin ([`ValveWiring::active_high`] for a stage that drives the pin
//! high instead). The eight inputs sit on one port (GPIOC: dump 1-4 on PC2-PC5, hold 1-4 on
//! PC9-PC12, [`DUMP_BITS`], [`HOLD_BITS`]; PC8 is the interface stage's output enable), so the step reads them with one load of GPIOC_IDR
//! ([`ValveLevels`]).
//!
//! **Debounce** (integrator per input, [`DEBOUNCE_TICKS`]): a tick with the input active
//! counts up, an inactive one down, between 0 and the limit; the state turns on at the limit
//! and off at 0. A clean edge so shows after [`DEBOUNCE_TICKS`] ticks (0.3 ms), a spike
//! shorter than that never shows, and a bouncing contact shows one edge.
//!
//! **Wiring.** Only the inputs the rig's configuration says are wired give a state; the others
//! are *not known* ([`ValveStates`]): an unwired pin reads as an idle coil, which would be a
//! plausible but false "valve closed". What is not wired is "not measured" downstream
//! (telemetry, frames, run logs, the WSP judge). The default is nothing wired.
//!
//! **Valve semantics** (the WSP valve of one wheelset, two coils): the hold coil closes the
//! supply to the cylinder, the dump coil opens the cylinder to the atmosphere. Venting is the
//! dump coil energised (whatever the hold coil does); holding is the hold coil energised
//! without the dump coil ([`ValveStates::venting`], [`ValveStates::holding`]).

use crate::WHEELSETS;

/// Debounce limit, ticks (0.3 ms at 10 kHz): a clean edge shows after this many ticks.
pub const DEBOUNCE_TICKS: u8 = 3;

/// Bit of each wheelset's dump-coil input in the port read ([`ValveLevels`]): PC2-PC5.
pub const DUMP_BITS: [u8; WHEELSETS] = [2, 3, 4, 5];
/// Bit of each wheelset's hold-coil input in the port read: PC9-PC12 (PC8, the next free
/// bit, is the output enable of issue 22).
pub const HOLD_BITS: [u8; WHEELSETS] = [9, 10, 11, 12];

/// Which valve inputs are wired and how the interface stage drives the pins.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ValveWiring {
    /// Bit j: the dump coil of wheelset j + 1 is wired.
    pub dump: u8,
    /// Bit j: the hold coil of wheelset j + 1 is wired.
    pub hold: u8,
    /// The stage drives the pin high while the coil is energised (default: low).
    pub active_high: bool,
}

impl ValveWiring {
    /// Every input wired, active low (the documented optocoupler stage).
    pub const ALL: Self = Self {
        dump: 0x0F,
        hold: 0x0F,
        active_high: false,
    };

    /// The `ValveWiring` configuration value (`RIG_COMMAND` `ConfigValue`): bits 0-3 dump
    /// wired, 4-7 hold wired, bit 8 active high.
    pub fn code(&self) -> u16 {
        (self.dump & 0x0F) as u16
            | ((self.hold & 0x0F) as u16) << 4
            | (self.active_high as u16) << 8
    }

    /// Inverse of [`ValveWiring::code`]; `None` when a bit above 8 is set.
    pub fn of_code(code: u16) -> Option<Self> {
        (code < 0x200).then(|| Self {
            dump: (code & 0x0F) as u8,
            hold: ((code >> 4) & 0x0F) as u8,
            active_high: code & 0x100 != 0,
        })
    }
}

/// The raw levels of the valve inputs' port (GPIOC_IDR's low 16 bits), as the step reads them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ValveLevels(pub u16);

impl ValveLevels {
    /// The levels a rig shows for these coil states (energised = true) through the
    /// interface stage of `wiring` (its polarity): for simulated rigs and tests. Pins of
    /// other functions read low.
    pub fn of_coils(
        dump: [bool; WHEELSETS],
        hold: [bool; WHEELSETS],
        wiring: &ValveWiring,
    ) -> Self {
        let mut levels = 0u16;
        for j in 0..WHEELSETS {
            for (energised, bit) in [(dump[j], DUMP_BITS[j]), (hold[j], HOLD_BITS[j])] {
                if energised == wiring.active_high {
                    levels |= 1 << bit;
                }
            }
        }
        Self(levels)
    }

    fn active(self, bit: u8, active_high: bool) -> bool {
        ((self.0 >> bit) & 1 != 0) == active_high
    }
}

/// The debounced valve states and which are known (wired). Bits j = wheelset j + 1.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ValveStates {
    /// Dump coil energised.
    pub dump: u8,
    /// Hold coil energised.
    pub hold: u8,
    /// The dump input is wired (its state is known).
    pub dump_known: u8,
    /// The hold input is wired.
    pub hold_known: u8,
}

impl ValveStates {
    /// The telemetry's `valves` word: bits 0-3 dump, 4-7 hold, 8-11 dump known, 12-15 hold
    /// known.
    pub fn bits(&self) -> u16 {
        let n = |x: u8| (x & 0x0F) as u16;
        n(self.dump) | n(self.hold) << 4 | n(self.dump_known) << 8 | n(self.hold_known) << 12
    }

    /// Inverse of [`ValveStates::bits`] (a state whose input is not known reads as off).
    pub fn of_bits(bits: u16) -> Self {
        let n = |shift: u16| ((bits >> shift) & 0x0F) as u8;
        let (dump_known, hold_known) = (n(8), n(12));
        Self {
            dump: n(0) & dump_known,
            hold: n(4) & hold_known,
            dump_known,
            hold_known,
        }
    }

    /// The states of a simulated unit's valves (all known): `venting` energises the dump
    /// and hold coils (supply closed, cylinder to atmosphere), `holding` the hold coil.
    pub fn of_unit(venting: [bool; WHEELSETS], holding: [bool; WHEELSETS]) -> Self {
        let mut s = Self {
            dump_known: 0x0F,
            hold_known: 0x0F,
            ..Self::default()
        };
        for j in 0..WHEELSETS {
            s.dump |= (venting[j] as u8) << j;
            s.hold |= ((venting[j] || holding[j]) as u8) << j;
        }
        s
    }

    /// Dump coil of wheelset `j` (0-based) energised; `None` when not wired.
    pub fn dump(&self, j: usize) -> Option<bool> {
        bit(self.dump, self.dump_known, j)
    }

    /// Hold coil of wheelset `j` energised; `None` when not wired.
    pub fn hold(&self, j: usize) -> Option<bool> {
        bit(self.hold, self.hold_known, j)
    }

    /// Wheelset `j` vents (its dump coil energised); `None` when the dump input is not wired.
    pub fn venting(&self, j: usize) -> Option<bool> {
        self.dump(j)
    }

    /// Wheelset `j` holds (hold coil energised, dump coil not); `None` unless both inputs
    /// are wired.
    pub fn holding(&self, j: usize) -> Option<bool> {
        Some(self.hold(j)? && !self.dump(j)?)
    }
}

fn bit(value: u8, known: u8, j: usize) -> Option<bool> {
    let m = 1u8.checked_shl(j as u32)?;
    (known & m != 0).then_some(value & m != 0)
}

/// The eight valve inputs with their debouncers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ValveInputs {
    wiring: ValveWiring,
    /// Integrator of each input: dump 0-3, hold 4-7.
    count: [u8; 2 * WHEELSETS],
    /// Debounced states: bits 0-3 dump, 4-7 hold.
    state: u8,
}

impl ValveInputs {
    /// Inputs of `wiring`, every state off.
    pub fn new(wiring: ValveWiring) -> Self {
        Self {
            wiring,
            ..Self::default()
        }
    }

    /// The wiring.
    pub fn wiring(&self) -> ValveWiring {
        self.wiring
    }

    /// Changes the wiring; every state starts again from off.
    pub fn set_wiring(&mut self, wiring: ValveWiring) {
        *self = Self::new(wiring);
    }

    /// One tick's sample of the port.
    #[inline]
    pub fn update(&mut self, levels: ValveLevels) {
        let wired = (self.wiring.dump & 0x0F) | (self.wiring.hold & 0x0F) << 4;
        for i in 0..2 * WHEELSETS {
            if wired & (1 << i) == 0 {
                continue;
            }
            let pin = if i < WHEELSETS {
                DUMP_BITS[i]
            } else {
                HOLD_BITS[i - WHEELSETS]
            };
            let c = &mut self.count[i];
            if levels.active(pin, self.wiring.active_high) {
                *c = (*c + 1).min(DEBOUNCE_TICKS);
                if *c == DEBOUNCE_TICKS {
                    self.state |= 1 << i;
                }
            } else {
                *c = c.saturating_sub(1);
                if *c == 0 {
                    self.state &= !(1 << i);
                }
            }
        }
    }

    /// The debounced states.
    pub fn states(&self) -> ValveStates {
        ValveStates {
            dump: self.state & 0x0F & self.wiring.dump,
            hold: (self.state >> 4) & self.wiring.hold & 0x0F,
            dump_known: self.wiring.dump & 0x0F,
            hold_known: self.wiring.hold & 0x0F,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(inputs: &mut ValveInputs, dump: [bool; 4], hold: [bool; 4], ticks: u32) {
        let levels = ValveLevels::of_coils(dump, hold, &inputs.wiring());
        for _ in 0..ticks {
            inputs.update(levels);
        }
    }

    #[test]
    fn a_clean_edge_shows_after_the_debounce_and_a_short_spike_never() {
        for active_high in [false, true] {
            let wiring = ValveWiring {
                active_high,
                ..ValveWiring::ALL
            };
            let mut v = ValveInputs::new(wiring);
            let on = [true, false, false, true];
            let off = [false; 4];
            run(&mut v, off, off, 10);
            assert_eq!(v.states().dump, 0);
            // Spikes of DEBOUNCE_TICKS - 1 ticks, each followed by as many quiet ones.
            for _ in 0..50 {
                run(&mut v, on, on, (DEBOUNCE_TICKS - 1) as u32);
                run(&mut v, off, off, (DEBOUNCE_TICKS - 1) as u32);
                assert_eq!(v.states().dump, 0, "active_high {active_high}");
                assert_eq!(v.states().hold, 0);
            }
            run(&mut v, off, off, 10);
            // A clean edge: off until the limit, on at it.
            run(&mut v, on, off, (DEBOUNCE_TICKS - 1) as u32);
            assert_eq!(v.states().dump, 0);
            run(&mut v, on, off, 1);
            assert_eq!(v.states().dump, 0b1001);
            assert_eq!(v.states().venting(0), Some(true));
            assert_eq!(v.states().venting(1), Some(false));
            // And off again DEBOUNCE_TICKS ticks after the coil drops.
            run(&mut v, off, off, (DEBOUNCE_TICKS - 1) as u32);
            assert_eq!(v.states().dump, 0b1001);
            run(&mut v, off, off, 1);
            assert_eq!(v.states().dump, 0);
        }
    }

    #[test]
    fn a_bouncing_contact_gives_one_edge() {
        let mut v = ValveInputs::new(ValveWiring::ALL);
        let mut edges = 0;
        let mut last = false;
        // A relay contact closing: 1-tick bounces for 1 ms, then closed.
        let pattern = [1, 0, 1, 1, 0, 1, 0, 1, 1, 1, 0, 1];
        for k in 0..100 {
            let closed = pattern.get(k).is_none_or(|&b| b == 1);
            run(&mut v, [closed; 4], [false; 4], 1);
            let now = v.states().dump & 1 != 0;
            edges += (now != last) as u32;
            last = now;
        }
        assert_eq!(edges, 1);
        assert!(last);
    }

    #[test]
    fn unwired_inputs_are_not_known_whatever_their_pins_show() {
        let wiring = ValveWiring {
            dump: 0b0011,
            hold: 0b0001,
            active_high: false,
        };
        let mut v = ValveInputs::new(wiring);
        run(&mut v, [true; 4], [true; 4], 10);
        let s = v.states();
        assert_eq!(s.dump, 0b0011);
        assert_eq!(s.hold, 0b0001);
        assert_eq!((s.dump(2), s.hold(1), s.holding(1)), (None, None, None));
        assert_eq!(s.venting(1), Some(true));
        // Vent with both coils energised is venting, not holding.
        assert_eq!(s.holding(0), Some(false));
        // Nothing wired (the default): nothing known.
        let mut none = ValveInputs::default();
        run(&mut none, [true; 4], [true; 4], 10);
        assert_eq!(none.states(), ValveStates::default());
    }

    #[test]
    fn telemetry_bits_and_configuration_codes_round_trip() {
        let s = ValveStates {
            dump: 0b0101,
            hold: 0b0111,
            dump_known: 0b1111,
            hold_known: 0b0111,
        };
        assert_eq!(ValveStates::of_bits(s.bits()), s);
        let unit = ValveStates::of_unit([true, false, false, false], [false, true, false, false]);
        assert_eq!(unit.venting(0), Some(true));
        assert_eq!(unit.holding(0), Some(false));
        assert_eq!(unit.holding(1), Some(true));
        assert_eq!(unit.venting(1), Some(false));
        for w in [
            ValveWiring::ALL,
            ValveWiring::default(),
            ValveWiring {
                dump: 0b1010,
                hold: 0b0110,
                active_high: true,
            },
        ] {
            assert_eq!(ValveWiring::of_code(w.code()), Some(w));
        }
        assert_eq!(ValveWiring::of_code(0x200), None);
    }

    proptest::proptest! {
        /// Any level sequence: the state changes only after DEBOUNCE_TICKS ticks in which
        /// the input was more often active than not since the last change (integrator).
        #[test]
        fn any_levels_never_show_a_state_without_its_input(
            levels in proptest::collection::vec(proptest::num::u16::ANY, 1..200)
        ) {
            let mut v = ValveInputs::new(ValveWiring::ALL);
            let mut run_active = [0u32; 8];
            for l in levels {
                v.update(ValveLevels(l));
                let s = v.states();
                for j in 0..4 {
                    for (i, bit, state) in [(j, DUMP_BITS[j], s.dump), (4 + j, HOLD_BITS[j], s.hold)] {
                        let active = (l >> bit) & 1 == 0;
                        run_active[i] = if active { run_active[i] + 1 } else { 0 };
                        // A steady input for the limit always shows.
                        if run_active[i] >= DEBOUNCE_TICKS as u32 {
                            proptest::prop_assert!(state & (1 << j) != 0);
                        }
                    }
                }
            }
        }
    }
}
