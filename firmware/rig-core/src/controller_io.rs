//! The controller-facing I/O of the rig beyond the wheel speeds (issue 21): its
//! configuration ([`IoConfig`], set item by item with `Configure` commands, [`IoItem`]) and
//! what the step drives ([`DrivenOutputs`]): the emergency brake loop, the service brake
//! demand PWM ([`crate::demand`]) and the two air-spring pressure DACs ([`crate::load`]).
//! The valve inputs are [`crate::valves`].
//!
//! **Safe outputs** ([`DrivenOutputs::safe`]): loop open (emergency brake), PWM line low
//! (no valid demand), DACs at 0 V (below the transducers' live zero). The step drives them in
//! every state but a rig-mode run (`Running`, `Finished`): idle, starting, stopped, fault,
//! self-test (the self-test's simulated unit closes its loop on the board; nothing it does
//! reaches a real controller), and the fault handlers and the reset leave the pins in the
//! same state (docs/rig.md).

use hils_brake_unit::BrakeDemand;
use num_enum::{IntoPrimitive, TryFromPrimitive};

use crate::demand::DemandConfig;
use crate::load::{BOGIES, LoadConfig};
use crate::pulse::{PulseRegisters, PulseTimer};
use crate::valves::ValveWiring;

/// The controller I/O configuration of the rig.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IoConfig {
    /// Which valve inputs are wired, and their polarity.
    pub valves: ValveWiring,
    /// The EB loop, the service demand PWM and the demand frame.
    pub demand: DemandConfig,
    /// The air-spring transducer signals.
    pub load: LoadConfig,
}

/// A `Configure` item of the controller I/O (`ConfigItem` codes 2-14 of `RIG_COMMAND`; the
/// 16-bit `ConfigValue` in the item's unit).
#[derive(Clone, Copy, Debug, PartialEq, Eq, IntoPrimitive, TryFromPrimitive)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum IoItem {
    /// [`ValveWiring::code`]: bits 0-3 dump wired, 4-7 hold wired, 8 active high.
    ValveWiring = 2,
    /// Service demand PWM frequency, Hz (1-20 000).
    PwmFrequency,
    /// Duty of no service demand, per mille (10-980).
    DutyRelease,
    /// Duty of the full scale, per mille (20-990; above the release duty).
    DutyFull,
    /// Full-scale deceleration, mm/s^2 (100-10 000).
    DemandFullScale,
    /// The controller's service brake steps (1-20).
    ServiceSteps,
    /// The controller's full service deceleration, mm/s^2 (100-10 000).
    FullService,
    /// Air-spring signal at 0 Pa, mV (0-10 000).
    LoadZero,
    /// Air-spring signal at full scale, mV (1-10 000; above the zero, within the stage's reach).
    LoadFull,
    /// Air-spring full scale, hPa (100-50 000).
    LoadFullScale,
    /// Stage gain DAC -> controller, per mille (500-10 000).
    LoadStageGain,
    /// Effective air-spring area of a bogie, cm^2 (100-20 000).
    AirSpringArea,
    /// Send `RIG_BRAKE_DEMAND` (0 or 1).
    DemandFrame,
}

impl IoItem {
    /// Every item, in code order.
    pub const ALL: [IoItem; 13] = [
        IoItem::ValveWiring,
        IoItem::PwmFrequency,
        IoItem::DutyRelease,
        IoItem::DutyFull,
        IoItem::DemandFullScale,
        IoItem::ServiceSteps,
        IoItem::FullService,
        IoItem::LoadZero,
        IoItem::LoadFull,
        IoItem::LoadFullScale,
        IoItem::LoadStageGain,
        IoItem::AirSpringArea,
        IoItem::DemandFrame,
    ];

    /// The values the item takes (checked when the frame is decoded).
    pub fn range(self) -> (u16, u16) {
        match self {
            IoItem::ValveWiring => (0, 0x1FF),
            IoItem::PwmFrequency => (1, 20_000),
            IoItem::DutyRelease => (10, 980),
            IoItem::DutyFull => (20, 990),
            IoItem::DemandFullScale | IoItem::FullService => (100, 10_000),
            IoItem::ServiceSteps => (1, 20),
            IoItem::LoadZero => (0, 10_000),
            IoItem::LoadFull => (1, 10_000),
            IoItem::LoadFullScale => (100, 50_000),
            IoItem::LoadStageGain => (500, 10_000),
            IoItem::AirSpringArea => (100, 20_000),
            IoItem::DemandFrame => (0, 1),
        }
    }

    /// Whether `value` is in the item's range.
    pub fn accepts(self, value: u16) -> bool {
        let (lo, hi) = self.range();
        (lo..=hi).contains(&value)
    }
}

/// Why an I/O configuration value was refused: it would make the configuration inconsistent
/// (the item named).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IoConfigError(pub IoItem);

/// mm/s^2 per m/s^2.
const MM_PER_M: f32 = 1000.0;

impl IoConfig {
    /// Nothing wired, the default demand and load signals.
    pub const DEFAULT: Self = Self {
        valves: ValveWiring {
            dump: 0,
            hold: 0,
            active_high: false,
        },
        demand: DemandConfig::DEFAULT,
        load: LoadConfig::DEFAULT,
    };

    /// The value of an item.
    pub fn value(&self, item: IoItem) -> u16 {
        let (d, l) = (&self.demand, &self.load);
        let mm = |x: f32| (x * MM_PER_M + 0.5) as u16;
        match item {
            IoItem::ValveWiring => self.valves.code(),
            IoItem::PwmFrequency => d.pwm_frequency_hz,
            IoItem::DutyRelease => d.duty_release_permille,
            IoItem::DutyFull => d.duty_full_permille,
            IoItem::DemandFullScale => mm(d.full_scale_mps2),
            IoItem::ServiceSteps => d.service_steps as u16,
            IoItem::FullService => mm(d.full_service_mps2),
            IoItem::LoadZero => l.zero_mv,
            IoItem::LoadFull => l.full_mv,
            IoItem::LoadFullScale => l.full_scale_hpa,
            IoItem::LoadStageGain => l.stage_gain_permille,
            IoItem::AirSpringArea => l.area_cm2,
            IoItem::DemandFrame => d.frame as u16,
        }
    }

    /// Sets an item (its value in range: [`IoItem::accepts`]); refused, with nothing
    /// changed, when the result would be inconsistent ([`IoConfig::check`]).
    pub fn set(&mut self, item: IoItem, value: u16) -> Result<(), IoConfigError> {
        let mut c = *self;
        if !(item.accepts(value) && c.assign(item, value)) {
            return Err(IoConfigError(item));
        }
        c.check().map_err(|_| IoConfigError(item))?;
        *self = c;
        Ok(())
    }

    /// Writes an item's value (in range) without the consistency check; `false` (nothing
    /// written) for a valve wiring code with bits above 8.
    pub fn assign(&mut self, item: IoItem, value: u16) -> bool {
        let (d, l) = (&mut self.demand, &mut self.load);
        match item {
            IoItem::ValveWiring => match ValveWiring::of_code(value) {
                Some(w) => self.valves = w,
                None => return false,
            },
            IoItem::PwmFrequency => d.pwm_frequency_hz = value,
            IoItem::DutyRelease => d.duty_release_permille = value,
            IoItem::DutyFull => d.duty_full_permille = value,
            IoItem::DemandFullScale => d.full_scale_mps2 = value as f32 / MM_PER_M,
            IoItem::ServiceSteps => d.service_steps = value as u8,
            IoItem::FullService => d.full_service_mps2 = value as f32 / MM_PER_M,
            IoItem::LoadZero => l.zero_mv = value,
            IoItem::LoadFull => l.full_mv = value,
            IoItem::LoadFullScale => l.full_scale_hpa = value,
            IoItem::LoadStageGain => l.stage_gain_permille = value,
            IoItem::AirSpringArea => l.area_cm2 = value,
            IoItem::DemandFrame => d.frame = value != 0,
        }
        true
    }

    /// Whether the configuration is consistent: every value in its item's range, the
    /// release duty below the full duty, the controller's full service deceleration within
    /// the PWM's full scale (above it the service steps could not be told apart), the
    /// transducer's zero below its full scale and the full scale within the stage's reach
    /// ([`LoadConfig::fits`]); the error names the first item that is not.
    pub fn check(&self) -> Result<(), IoConfigError> {
        if let Some(&item) = IoItem::ALL.iter().find(|&&i| !i.accepts(self.value(i))) {
            return Err(IoConfigError(item));
        }
        if self.demand.duty_release_permille >= self.demand.duty_full_permille {
            return Err(IoConfigError(IoItem::DutyRelease));
        }
        if self.value(IoItem::FullService) > self.value(IoItem::DemandFullScale) {
            return Err(IoConfigError(IoItem::FullService));
        }
        if !self.load.fits() {
            return Err(IoConfigError(IoItem::LoadFull));
        }
        Ok(())
    }

    /// The items that make this configuration from the default, in an order every
    /// configuration accepts one by one (the signal's bounds widened first, then narrowed).
    pub fn items(&self) -> [(IoItem, u16); 18] {
        use IoItem::*;
        let v = |i| (i, self.value(i));
        [
            // Duty, full scale and transducer bounds first to their widest, so no
            // intermediate state is inconsistent whatever the order of the old and new
            // values.
            (DutyRelease, 10),
            (DutyFull, 990),
            (DemandFullScale, IoItem::DemandFullScale.range().1),
            (LoadStageGain, 10_000),
            (LoadZero, 0),
            v(LoadFull),
            v(LoadZero),
            v(LoadStageGain),
            v(DutyFull),
            v(DutyRelease),
            v(ValveWiring),
            v(PwmFrequency),
            v(ServiceSteps),
            v(FullService),
            v(DemandFullScale),
            v(LoadFullScale),
            v(AirSpringArea),
            v(DemandFrame),
        ]
    }

    /// What the step drives during a rig-mode run under `brake`, with the plant's
    /// air-spring forces (N, bogie 1 first).
    pub fn driven(
        &self,
        timer: &PulseTimer,
        brake: BrakeDemand,
        air_spring_n: [f32; BOGIES],
    ) -> DrivenOutputs {
        self.driven_in(self.demand.pwm_period(timer), brake, air_spring_n)
    }

    /// [`Self::driven`] with the PWM's period computed once for this configuration
    /// ([`DemandConfig::pwm_period`]): what the 10 kHz step calls.
    pub fn driven_in(
        &self,
        pwm_period: PulseRegisters,
        brake: BrakeDemand,
        air_spring_n: [f32; BOGIES],
    ) -> DrivenOutputs {
        let service_mps2 = self.demand.service_mps2(brake);
        let air_spring_pa = air_spring_n.map(|f| self.load.pressure_pa(f));
        DrivenOutputs {
            eb_loop_closed: brake != BrakeDemand::Emergency,
            service_mps2,
            pwm: self.demand.pwm_in(pwm_period, service_mps2),
            air_spring_pa,
            dac: air_spring_pa.map(|p| self.load.dac_code(p)),
        }
    }
}

impl Default for IoConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// What the step drives on the controller's demand and load lines.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DrivenOutputs {
    /// The EB loop relay is energised (loop closed: no emergency brake).
    pub eb_loop_closed: bool,
    /// Service deceleration on the PWM, m/s^2 (0 while silent).
    pub service_mps2: f32,
    /// The PWM timer's registers (silent: CCR 0, line low).
    pub pwm: PulseRegisters,
    /// Air-spring pressure of each bogie shown on the DACs, Pa (NaN while silent).
    pub air_spring_pa: [f32; BOGIES],
    /// DAC codes (0 while silent: 0 V).
    pub dac: [u16; BOGIES],
}

impl DrivenOutputs {
    /// The safe outputs: loop open, PWM line low, DACs at 0 V.
    pub fn safe(timer: &PulseTimer) -> Self {
        Self {
            eb_loop_closed: false,
            service_mps2: 0.0,
            pwm: timer.silent(),
            air_spring_pa: [f32::NAN; BOGIES],
            dac: [0; BOGIES],
        }
    }

    /// Whether these are the safe outputs (loop open, PWM and DACs silent).
    pub fn is_safe(&self) -> bool {
        !self.eb_loop_closed && self.pwm.is_silent() && self.dac == [0; BOGIES]
    }

    /// The telemetry's `driven` bits: 0 loop closed, 1 PWM active, 2 DACs active.
    pub fn bits(&self) -> u8 {
        self.eb_loop_closed as u8
            | (!self.pwm.is_silent() as u8) << 1
            | ((self.dac != [0; BOGIES]) as u8) << 2
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_item_round_trips_and_the_items_rebuild_any_configuration() {
        let mut target = IoConfig::DEFAULT;
        target.valves = ValveWiring::ALL;
        target.demand.duty_release_permille = 950;
        target.demand.duty_full_permille = 980;
        target.demand.frame = true;
        target.load.zero_mv = 4000;
        target.load.full_mv = 9000;
        target.load.stage_gain_permille = 3000;
        // A narrower PWM full scale and a higher full service, each within the other.
        target.demand.full_scale_mps2 = 1.2;
        target.demand.full_service_mps2 = 1.2;
        let mut c = IoConfig::DEFAULT;
        for (item, v) in target.items() {
            c.set(item, v).unwrap_or_else(|e| panic!("{e:?} = {v}"));
        }
        assert_eq!(c, target);
        for item in IoItem::ALL {
            assert!(item.accepts(target.value(item)), "{item:?}");
        }
    }

    #[test]
    fn an_inconsistent_value_is_refused_and_changes_nothing() {
        let mut c = IoConfig::DEFAULT;
        assert_eq!(
            c.set(IoItem::DutyRelease, 900),
            Err(IoConfigError(IoItem::DutyRelease))
        );
        assert_eq!(
            c.set(IoItem::LoadStageGain, 1000),
            Err(IoConfigError(IoItem::LoadStageGain))
        );
        assert_eq!(
            c.set(IoItem::PwmFrequency, 0),
            Err(IoConfigError(IoItem::PwmFrequency))
        );
        // A full service deceleration above the PWM's full scale (1.5 m/s^2), and a full
        // scale below the full service (1.0 m/s^2).
        assert_eq!(
            c.set(IoItem::FullService, 1600),
            Err(IoConfigError(IoItem::FullService))
        );
        assert_eq!(
            c.set(IoItem::DemandFullScale, 900),
            Err(IoConfigError(IoItem::DemandFullScale))
        );
        assert_eq!(c, IoConfig::DEFAULT);
    }

    #[test]
    fn driven_outputs_follow_the_command_and_the_safe_ones_are_silent() {
        let c = IoConfig::DEFAULT;
        let t = PulseTimer::timer16(170_000_000);
        let safe = DrivenOutputs::safe(&t);
        assert!(safe.is_safe());
        assert_eq!(safe.bits(), 0);
        let f = [0.5 * 35_000.0 * 9.81; 2];
        let eb = c.driven(&t, BrakeDemand::Emergency, f);
        assert!(!eb.eb_loop_closed && !eb.pwm.is_silent() && eb.dac[0] > 0);
        assert_eq!(eb.bits(), 0b110);
        let rel = c.driven(&t, BrakeDemand::Release, f);
        assert!(rel.eb_loop_closed && rel.service_mps2 == 0.0);
        let sb = c.driven(
            &t,
            BrakeDemand::Service {
                deceleration_mps2: 0.8,
            },
            f,
        );
        assert!(sb.eb_loop_closed && (sb.service_mps2 - 0.8).abs() < 1e-6);
        assert_eq!(sb.bits(), 0b111);
        assert!(!sb.is_safe() && !eb.is_safe() && !rel.is_safe());
    }
}
