//! The brake demand the board gives the controller, as a train gives it: the emergency brake
//! loop and the service brake demand on a PWM train line (and, optionally, on a CAN frame,
//! `RIG_BRAKE_DEMAND` in `hils.dbc`).
//!
//! **Emergency brake loop** (fail-safe): a digital output drives the coil of a safety relay
//! whose contact closes the controller's EB loop. Energised (output high) = loop closed = no
//! emergency brake; de-energised = loop open = emergency brake. The relay driver has a
//! pull-down, so in reset, with the pin high-impedance, the loop is open; the board opens it
//! in the safe state and on every fault (docs/rig.md, "Controller I/O").
//!
//! **Service brake demand** (PWM, a live-zero signal): duty [`DemandConfig::duty_release_permille`]
//! (default 10 %) = no service demand, [`DemandConfig::duty_full_permille`] (90 %) = the full
//! scale [`DemandConfig::full_scale_mps2`] of deceleration, linear between; 0 % or 100 % (a
//! line stuck low or high, or the board silent) is no valid demand, so a controller that
//! reads it brakes. A service step n of the controller's `service_steps` is the deceleration
//! n / steps of [`DemandConfig::full_service_mps2`] (the reference brake unit's 7 steps of
//! 1.0 m/s^2). EB and release give the release duty (the loop carries the EB).
//!
//! The controller's side ([`ControllerDemand`]) is here too: the simulated controller of
//! `hils rig --interface sim` reads the loop and the PWM registers through it, so the whole
//! path runs through this one code.

use hils_brake_unit::BrakeDemand;

use crate::pulse::{PulseRegisters, PulseTimer};

/// The service brake demand's PWM and the optional demand frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DemandConfig {
    /// PWM frequency, Hz (1-20 000).
    pub pwm_frequency_hz: u16,
    /// Duty of no service demand, per mille.
    pub duty_release_permille: u16,
    /// Duty of the full scale, per mille.
    pub duty_full_permille: u16,
    /// Deceleration demanded at the full-scale duty, m/s^2.
    pub full_scale_mps2: f32,
    /// The controller's service brake steps (a `ServiceStep` n is n / steps of the full
    /// service deceleration).
    pub service_steps: u8,
    /// The controller's full service deceleration, m/s^2.
    pub full_service_mps2: f32,
    /// Also send `RIG_BRAKE_DEMAND` (every 10 ms).
    pub frame: bool,
}

impl DemandConfig {
    /// 500 Hz, 10 % .. 90 % for 0 .. 1.5 m/s^2, the reference brake unit's service steps
    /// (`[brake_unit]`: 7 steps up to 1.0 m/s^2; a test keeps them equal), no frame.
    pub const DEFAULT: Self = Self {
        pwm_frequency_hz: 500,
        duty_release_permille: 100,
        duty_full_permille: 900,
        full_scale_mps2: 1.5,
        service_steps: 7,
        full_service_mps2: 1.0,
        frame: false,
    };
}

impl Default for DemandConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Below this share of the full scale a decoded demand is no service demand (release).
const RELEASE_SHARE: f32 = 1e-3;
/// A duty this far (share of the span) outside release .. full is no valid demand.
const DUTY_TOLERANCE_SHARE: f32 = 0.02;

impl DemandConfig {
    /// The service deceleration a brake command asks of the PWM, m/s^2 (0 for release and
    /// EB: the loop carries the EB), limited to 0 .. the full scale.
    pub fn service_mps2(&self, brake: BrakeDemand) -> f32 {
        let a = match brake {
            BrakeDemand::Release | BrakeDemand::Emergency => 0.0,
            BrakeDemand::Service { deceleration_mps2 } => deceleration_mps2,
            BrakeDemand::ServiceStep { step } => {
                let steps = self.service_steps.max(1);
                self.full_service_mps2 * step.min(steps) as f32 / steps as f32
            }
        };
        if a.is_finite() {
            a.clamp(0.0, self.full_scale_mps2)
        } else {
            0.0
        }
    }

    /// Duty of a service deceleration, 0..1.
    fn duty(&self, service_mps2: f32) -> f32 {
        let share = (service_mps2 / self.full_scale_mps2).clamp(0.0, 1.0);
        let (lo, hi) = self.duty_span();
        lo + (hi - lo) * if share.is_finite() { share } else { 0.0 }
    }

    fn duty_span(&self) -> (f32, f32) {
        (
            self.duty_release_permille as f32 * 1e-3,
            self.duty_full_permille as f32 * 1e-3,
        )
    }

    /// The PWM timer's registers for a service deceleration (m/s^2).
    pub fn pwm(&self, timer: &PulseTimer, service_mps2: f32) -> PulseRegisters {
        self.pwm_in(self.pwm_period(timer), service_mps2)
    }

    /// The PWM's prescaler and period at the configured frequency: they depend on the
    /// configuration only, so the step computes them once per configuration. Without a
    /// fraction: the demand is the duty, and an undithered period keeps PSC and ARR written
    /// once (`pulse::PulseChannel` dithers only a setting with a fraction).
    pub fn pwm_period(&self, timer: &PulseTimer) -> PulseRegisters {
        PulseRegisters {
            arr_frac: 0,
            ..timer.registers(self.pwm_frequency_hz as f32)
        }
    }

    /// [`Self::pwm`] in a period from [`Self::pwm_period`]: the duty's compare value only.
    pub fn pwm_in(&self, period: PulseRegisters, service_mps2: f32) -> PulseRegisters {
        let mut r = period;
        let counts = r.arr as f32 + 1.0;
        r.ccr = ((self.duty(service_mps2) * counts + 0.5) as u32).min(r.arr);
        r
    }

    /// The service deceleration a controller reads from PWM registers (duty = CCR / (ARR +
    /// 1)), m/s^2; `None` for a silent line or a duty outside release .. full by more than
    /// 2 % of the span (a line stuck low or high: no valid demand).
    pub fn decode_pwm(&self, r: &PulseRegisters) -> Option<f32> {
        if r.is_silent() {
            return None;
        }
        let duty = r.ccr as f32 / (r.arr as f32 + 1.0);
        let (lo, hi) = self.duty_span();
        let share = (duty - lo) / (hi - lo);
        let tol = DUTY_TOLERANCE_SHARE;
        (share >= -tol && share <= 1.0 + tol).then(|| share.clamp(0.0, 1.0) * self.full_scale_mps2)
    }
}

/// What a controller reads from the train lines: the EB loop and the service demand.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerDemand {
    /// The EB loop is closed (energised): no emergency brake.
    pub eb_loop_closed: bool,
    /// The service deceleration on the PWM, m/s^2 (`None`: no valid demand).
    pub service_mps2: Option<f32>,
}

impl ControllerDemand {
    /// The brake demand a controller acts on: emergency while the loop is open or the PWM
    /// carries no valid demand (fail-safe), release below 0.1 % of the full scale, else the
    /// service deceleration.
    pub fn brake(&self, config: &DemandConfig) -> BrakeDemand {
        match (self.eb_loop_closed, self.service_mps2) {
            (true, Some(a)) if a <= RELEASE_SHARE * config.full_scale_mps2 => BrakeDemand::Release,
            (true, Some(a)) => BrakeDemand::Service {
                deceleration_mps2: a,
            },
            _ => BrakeDemand::Emergency,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn timer() -> PulseTimer {
        PulseTimer::timer16(170_000_000)
    }

    #[test]
    fn the_pwm_carries_each_command_and_the_controller_reads_it_back() {
        let c = DemandConfig::default();
        let t = timer();
        for (brake, a) in [
            (BrakeDemand::Release, 0.0),
            (BrakeDemand::Emergency, 0.0),
            (
                BrakeDemand::Service {
                    deceleration_mps2: 0.8,
                },
                0.8,
            ),
            (BrakeDemand::ServiceStep { step: 7 }, 1.0),
            (BrakeDemand::ServiceStep { step: 3 }, 3.0 / 7.0),
            // Above the full scale: held at it.
            (
                BrakeDemand::Service {
                    deceleration_mps2: 4.0,
                },
                1.5,
            ),
        ] {
            assert!((c.service_mps2(brake) - a).abs() < 1e-6, "{brake:?}");
            let r = c.pwm(&t, c.service_mps2(brake));
            // 500 Hz exactly enough: 170 MHz / ((PSC + 1)(ARR + 1)).
            let f = 170e6 / ((r.psc as f64 + 1.0) * (r.arr as f64 + 1.0));
            assert!((f - 500.0).abs() < 0.01, "{f} Hz");
            let back = c.decode_pwm(&r).unwrap();
            // One timer count of 56 667: 2.6e-5 of the full scale.
            assert!((back - a).abs() < 1e-4 * 1.5, "{brake:?}: {back} vs {a}");
        }
        // Duty at release and full scale, from the registers (an independent formula).
        let duty = |a: f32| {
            let r = c.pwm(&t, a);
            r.ccr as f64 / (r.arr as f64 + 1.0)
        };
        assert!((duty(0.0) - 0.1).abs() < 1e-4 && (duty(1.5) - 0.9).abs() < 1e-4);
    }

    #[test]
    fn the_default_service_steps_are_the_reference_brake_units() {
        let unit = hils_brake_unit::BrakeUnitParams::default();
        let c = DemandConfig::DEFAULT;
        assert_eq!(c.service_steps, unit.service_steps);
        assert_eq!(
            c.full_service_mps2 as f64,
            unit.full_service_deceleration_mps2
        );
    }

    #[test]
    fn a_silent_or_stuck_line_is_no_demand_and_the_controller_brakes() {
        let c = DemandConfig::default();
        let t = timer();
        assert_eq!(c.decode_pwm(&t.silent()), None);
        let mut stuck_high = c.pwm(&t, 0.0);
        stuck_high.ccr = stuck_high.arr;
        assert_eq!(c.decode_pwm(&stuck_high), None);
        let mut low = c.pwm(&t, 0.0);
        low.ccr = 1;
        assert_eq!(c.decode_pwm(&low), None);
        let read = |eb_loop_closed, service_mps2| {
            ControllerDemand {
                eb_loop_closed,
                service_mps2,
            }
            .brake(&c)
        };
        assert_eq!(read(false, Some(0.5)), BrakeDemand::Emergency);
        assert_eq!(read(true, None), BrakeDemand::Emergency);
        assert_eq!(read(true, Some(0.0)), BrakeDemand::Release);
        assert_eq!(
            read(true, Some(0.5)),
            BrakeDemand::Service {
                deceleration_mps2: 0.5
            }
        );
    }

    proptest::proptest! {
        #[test]
        fn any_demand_and_frequency_round_trips_within_a_count(
            a in 0.0f32..1.5, f in 1u16..=20_000, lo in 10u16..400, hi in 600u16..990
        ) {
            let c = DemandConfig { pwm_frequency_hz: f, duty_release_permille: lo, duty_full_permille: hi, ..Default::default() };
            let r = c.pwm(&timer(), a);
            let back = c.decode_pwm(&r).unwrap();
            let count = c.full_scale_mps2 / ((hi - lo) as f32 * 1e-3 * (r.arr as f32 + 1.0));
            proptest::prop_assert!((back - a).abs() <= count + 1e-5, "{} vs {}", back, a);
        }
    }
}
