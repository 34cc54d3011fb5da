//! The handoff protocol under real concurrency: a builder thread publishes values into
//! slots while a "step" thread takes them over and retires the old ones. Every value the
//! step sees must be complete (never half written, never overwritten while in use) and the
//! values must arrive in order.

use std::cell::UnsafeCell;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use hils_rig_core::handoff::SlotStates;

const WORDS: usize = 64;
const VALUES: u64 = 3_000;

struct Storage {
    states: SlotStates<2>,
    slots: [UnsafeCell<[u64; WORDS]>; 2],
}

// SAFETY (test): the protocol under test decides who may touch a slot.
unsafe impl Sync for Storage {}

#[test]
fn builder_and_step_never_share_a_slot() {
    let st = Arc::new(Storage {
        states: SlotStates::new(),
        slots: [UnsafeCell::new([0; WORDS]), UnsafeCell::new([0; WORDS])],
    });
    let done = Arc::new(AtomicBool::new(false));

    let builder = {
        let st = st.clone();
        std::thread::spawn(move || {
            let mut next = 1u64;
            while next <= VALUES {
                let Some(c) = st.states.claim() else {
                    std::thread::yield_now();
                    continue;
                };
                // The builder owns the slot: write the value word by word.
                let p = st.slots[c.slot].get();
                for w in 0..WORDS {
                    unsafe { (*p)[w] = next };
                    if w % 16 == 0 {
                        std::thread::yield_now();
                    }
                }
                assert!(st.states.publish(c.slot));
                next += 1;
            }
        })
    };

    let step = {
        let st = st.clone();
        let done = done.clone();
        std::thread::spawn(move || {
            let mut last = 0u64;
            let mut active: Option<usize> = None;
            let mut ticks = 0u64;
            while last < VALUES {
                ticks += 1;
                match st.states.take() {
                    Some(new) => {
                        if let Some(old) = active.replace(new) {
                            assert!(st.states.retire(old));
                        }
                    }
                    None => std::thread::yield_now(),
                }
                if let Some(a) = active {
                    // The step owns the active slot: every word holds the same value.
                    let v = unsafe { &*st.slots[a].get() };
                    let first = v[0];
                    assert!(v.iter().all(|&w| w == first), "torn value in slot {a}");
                    // One value in flight at a time: each arrives, in order, none skipped.
                    assert!(first == last || first == last + 1, "{first} after {last}");
                    assert_eq!(st.states.active(), Some(a));
                    last = first;
                }
            }
            done.store(true, Ordering::Release);
            ticks
        })
    };

    builder.join().unwrap();
    let ticks = step.join().unwrap();
    assert!(done.load(Ordering::Acquire));
    assert!(ticks >= VALUES);
}
