//! Invariants the fuzz targets check (not just "no panic"), and a small byte cursor that
//! turns the fuzzer's bytes into typed values.

use hils::measured::{Measured, RunLog};

/// Reads typed values from the fuzzer's bytes (zeros once they run out).
pub struct Bytes<'a>(pub &'a [u8]);

impl Bytes<'_> {
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
    pub fn u8(&mut self) -> u8 {
        match self.0.split_first() {
            Some((b, rest)) => {
                self.0 = rest;
                *b
            }
            None => 0,
        }
    }
    pub fn u16(&mut self) -> u16 {
        u16::from_le_bytes([self.u8(), self.u8()])
    }
    pub fn u32(&mut self) -> u32 {
        u32::from_le_bytes([self.u8(), self.u8(), self.u8(), self.u8()])
    }
    /// Any f32 bit pattern (NaN, inf, subnormals included).
    pub fn f32(&mut self) -> f32 {
        f32::from_bits(self.u32())
    }
    /// A value in [lo, hi] from one byte.
    pub fn within(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.u8() as f64 / 255.0
    }
    pub fn take(&mut self, n: usize) -> &[u8] {
        let n = n.min(self.0.len());
        let (a, b) = self.0.split_at(n);
        self.0 = b;
        a
    }
}

/// After a successful read: time finite and strictly increasing, every channel as long as
/// the time, every measured value finite and within the column's plausible range.
pub fn check_run_log(r: &RunLog) {
    let t = &r.t_s;
    assert!(!t.is_empty(), "a run log read without rows");
    assert!(t.iter().all(|x| x.is_finite()), "non-finite time");
    assert!(t.windows(2).all(|w| w[1] > w[0]), "time not increasing");
    let n = t.len();
    let check = |name: &str, v: &[f64]| {
        assert_eq!(v.len(), n, "{name}: length");
        for x in v {
            assert!(x.is_nan() || x.is_finite(), "{name}: {x}");
            if let Some(range) = hils::measured::plausible_range(name) {
                assert!(
                    x.is_nan() || range.contains(x),
                    "{name}: {x} outside {range:?}"
                );
            }
        }
    };
    check("v_ref_mps", &r.v_ref_mps);
    // Empty v_ref cells are allowed (spec/measured-data.md: "Empty cells mean not measured
    // at this sample"; a radar drops out): NaN there, checked finite or NaN above.
    for (j, w) in r.omega_radps.iter().enumerate() {
        check(&format!("omega{}_radps", j + 1), w);
    }
    use hils_sil::record::run_log as rl;
    for (c, per) in [
        (rl::P_CYL, &r.p_cyl_pa),
        (rl::F_CLAMP, &r.f_clamp_n),
        (rl::F_BRAKE, &r.f_brake_n),
        (rl::T_DISC, &r.t_disc_c),
        (rl::Q, &r.q_n),
        (rl::WSP, &r.wsp),
    ] {
        for (j, col) in per.iter().enumerate() {
            if let Some(v) = col {
                check(&c.name(j).to_string(), v);
            }
        }
    }
    if let Some(a) = &r.a_x_mps2 {
        check("a_x_mps2", a);
    }
    if let Some(c) = &r.cmd {
        assert_eq!(c.len(), n, "cmd: length");
    }
}

/// Checks either kind of measured file after a successful read.
pub fn check_measured(m: &Measured) {
    match m {
        Measured::Run(r) => check_run_log(r),
        Measured::Friction(f) => {
            let n = f.mu.len();
            assert!(n > 0);
            assert_eq!(f.v_friction_mps.len(), n);
            assert_eq!(f.t_disc_c.len(), n);
            assert!(
                f.mu.iter().all(|m| (0.0..=2.0).contains(m)),
                "mu outside [0, 2]"
            );
            assert!(f.v_friction_mps.iter().all(|x| x.is_finite()));
            assert!(f.t_disc_c.iter().all(|x| x.is_finite()));
            if let Some(t) = &f.t_s {
                assert_eq!(t.len(), n);
                assert!(t.iter().all(|x| x.is_finite()));
                assert!(t.windows(2).all(|w| w[1] > w[0]), "time not increasing");
            }
        }
    }
}
