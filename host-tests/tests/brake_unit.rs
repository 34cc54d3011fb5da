//! The simulated brake unit in a whole `hils simulate` run: the WSP keeps every lock short
//! on a slippery rail. (The unit alone: `firmware/brake-unit/tests/unit.rs`; in the loop:
//! `firmware/sil/tests/brake_unit.rs`.)

use hils::scenario::{EbOptions, run_eb};
use hils_sil::ParamFile;

#[test]
fn lock_duration_stays_bounded_on_a_slippery_rail() {
    // Half the wet adhesion: every wheelset slides repeatedly; WSP keeps each lock short.
    let mut p = ParamFile::default();
    p.plant.contact.mu_0 = 0.105;
    let mut opts = EbOptions::paper(&p);
    opts.record_every = 100;
    let run = run_eb::<f32>(&p, &opts).unwrap();
    assert_eq!(run.summary.slides, vec![1, 2, 3, 4]);
    for (j, lock) in run.longest_lock_s.iter().enumerate() {
        assert!(*lock <= 0.4, "wheelset {}: locked for {lock} s", j + 1);
    }
    assert!(run.summary.stop_time_s.is_some(), "stops");
}
