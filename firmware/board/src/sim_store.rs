//! The rig's simulation store on the board: a static the builder task fills in place, in
//! thread mode, while the rig has lent it (`hils_rig_core::rig::SimStore`), so the step
//! never moves the ~6 KiB simulation (review of issue 11: two 6 KiB copies in the step on
//! the tick a run began).
//!
//! Ownership: the step's rig uses the store except between `Rig::take_start_request`
//! (the request goes to the builder through `START_REQUESTS`) and `Rig::install_in_place`
//! (the builder's `Built` arrives through `BUILT`, published with release after the build
//! is written, taken with acquire). In between only the builder writes it, and the rig
//! touches nothing of it (host test `the_rig_leaves_a_lent_store_alone`).

use core::cell::UnsafeCell;
use core::mem::MaybeUninit;

use hils_rig_core::rig::{SimStore, Simulation};

/// Uninitialised until [`BoardSim::new`] (so the 6 KiB are in .bss, not a .data image in
/// flash).
struct Slot(UnsafeCell<MaybeUninit<Simulation>>);

// SAFETY: accessed by one context at a time, as the module documents (the step's rig
// while it owns the store, the builder while the rig has lent it).
unsafe impl Sync for Slot {}

static SLOT: Slot = Slot(UnsafeCell::new(MaybeUninit::uninit()));

/// The step rig's handle on [`SLOT`]; one exists (made once in `app.rs`).
pub struct BoardSim(());

impl BoardSim {
    /// Initialises the store (no run).
    ///
    /// # Safety
    /// Call once, before the step runs: the handle goes into the step's rig, the only
    /// user besides the builder.
    pub unsafe fn new() -> Self {
        // SAFETY: nobody else uses the store yet (caller's contract).
        unsafe { (*SLOT.0.get()).write(Simulation::none()) };
        Self(())
    }
}

impl SimStore for BoardSim {
    fn sim(&self) -> &Simulation {
        // SAFETY: the rig calls this only while it owns the store (module doc); `new`
        // initialised it.
        unsafe { (*SLOT.0.get()).assume_init_ref() }
    }
    fn sim_mut(&mut self) -> &mut Simulation {
        // SAFETY: as above.
        unsafe { (*SLOT.0.get()).assume_init_mut() }
    }
}

/// The builder (thread mode): the store, to build a requested run into.
///
/// # Safety
/// Only between receiving a request from `START_REQUESTS` and publishing its `Built`, and
/// the reference must not outlive that.
pub unsafe fn lent_store() -> &'static mut Simulation {
    // SAFETY: the rig has lent the store (caller's contract) and does not touch it; the
    // rig's `BoardSim::new` initialised it before.
    unsafe { (*SLOT.0.get()).assume_init_mut() }
}
