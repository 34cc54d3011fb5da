//! Storage for values handed from thread mode to the step (`hils_rig_core::handoff`: the
//! slot protocol; here: the slots and the memory access it permits).
//!
//! Used for the rig and its peripherals (built in `main`, used in place by the step from
//! its first tick: [`Handoff::step_value`]) and for the simulation of each run (built by
//! the builder task in thread mode when the step requests a start, moved into the rig by
//! the step at its next tick: [`Handoff::step_take`]).

use core::cell::UnsafeCell;
use core::mem::MaybeUninit;

use hils_rig_core::handoff::SlotStates;

/// No slot free, or a published value still waits for the step.
#[derive(Clone, Copy, Debug, defmt::Format)]
pub struct Busy;

/// `N` slots for values of type `T`.
pub struct Handoff<T, const N: usize> {
    states: SlotStates<N>,
    slots: [UnsafeCell<MaybeUninit<T>>; N],
}

// SAFETY: a slot's memory is touched only by the context that owns it under `SlotStates`
// (the builder while `Building`, the step while `Active`); the states' acquire/release
// transitions order those accesses. `T: Send` because the value moves between contexts.
unsafe impl<T: Send, const N: usize> Sync for Handoff<T, N> {}

impl<T, const N: usize> Handoff<T, N> {
    pub const fn new() -> Self {
        Self {
            states: SlotStates::new(),
            slots: [const { UnsafeCell::new(MaybeUninit::uninit()) }; N],
        }
    }

    /// Builder (thread mode): builds a value into a free slot and publishes it for the
    /// step. `build` runs only if a slot was free.
    pub fn publish_with(&self, build: impl FnOnce() -> T) -> Result<(), Busy> {
        let claim = self.states.claim().ok_or(Busy)?;
        let slot = self.slots[claim.slot].get();
        // SAFETY: the claim makes this context the slot's only user until `publish`; a
        // retired slot still holds the step's old value, dropped here.
        unsafe {
            if claim.holds_old_value {
                (*slot).assume_init_drop();
            }
            (*slot).write(build());
        }
        self.states.publish(claim.slot);
        Ok(())
    }

    /// The step: moves a newly published value out, if any, and frees its slot at once
    /// (for values the step keeps in its own memory: the simulation of a run).
    ///
    /// # Safety
    /// Only the step interrupt calls this (one context, not re-entrant).
    #[inline(always)]
    pub unsafe fn step_take(&self) -> Option<T> {
        let i = self.states.take()?;
        // SAFETY: `take` gave this context the slot, fully written before the builder's
        // publish (release); after the read the slot is marked free, so nobody drops the
        // moved-out value again.
        let value = unsafe { (*self.slots[i].get()).assume_init_read() };
        self.states.release(i);
        Some(value)
    }

    /// Thread mode: runs `f` on the value the step uses, with the step masked (the
    /// [`crate::ceiling::StepCeiling`] lock: BASEPRI at the step's priority), for short
    /// work the step must not do itself (restarting the ADC ring). `None` before the step
    /// took its first value.
    ///
    /// # Safety
    /// Only thread mode (or a context below the step's priority) calls this, and `f` is
    /// short: the step waits for it.
    pub unsafe fn with_step_masked<R>(&self, f: impl FnOnce(&mut T) -> R) -> Option<R> {
        use embassy_sync::blocking_mutex::raw::RawMutex;
        crate::ceiling::StepCeiling::INIT.lock(|| {
            let i = self.states.active()?;
            // SAFETY: the step, the `Active` slot's owner, cannot run while the ceiling
            // masks it, and holds no reference between its ticks; thread mode cannot be
            // preempted by another user of the slot.
            Some(f(unsafe { (*self.slots[i].get()).assume_init_mut() }))
        })
    }

    /// The step: the value it uses, switching to a newly published one first (the slot it
    /// used before is retired for the builder to reuse).
    ///
    /// # Safety
    /// Only the step interrupt calls this (one context, not re-entrant), and it drops the
    /// reference before returning from the interrupt.
    #[inline(always)]
    pub unsafe fn step_value(&self) -> Option<&mut T> {
        let old = self.states.active();
        if self.states.take().is_some()
            && let Some(old) = old
        {
            self.states.retire(old);
        }
        let i = self.states.active()?;
        // SAFETY: `Active` slots belong to the step; `take` made it so after the builder's
        // publish (release) of a fully written value.
        Some(unsafe { (*self.slots[i].get()).assume_init_mut() })
    }
}
