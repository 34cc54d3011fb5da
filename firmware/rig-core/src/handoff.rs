//! Handing a value built in thread mode to the step interrupt without copying it and
//! without a lock: the ownership protocol of `N` storage slots.
//!
//! The step must do only the step (issue 11: building a simulation in the step costs
//! ~35 000 instructions and a 13.7 KB stack frame). So a low-priority builder constructs the
//! value in place, in a static slot, and publishes it; the step takes it over at its next
//! tick by switching which slot it uses, in constant time. Each slot's state is one atomic:
//!
//! ```text
//!   Free/Retired --claim (builder)--> Building --publish--> Ready --take (step)--> Active
//!        ^                               |                                            |
//!        +-----------abandon-------------+              <----retire (step)------------+
//!   Free <--release (step: the value was moved out)-------------------------------- Active
//! ```
//!
//! Whoever moved a slot into a state owns its memory in that state: the builder in
//! `Building` (it may drop the old value of a `Retired` slot and write the new one), the
//! step in `Active`; nobody touches a `Ready` slot but the step's `take`. Transitions use
//! acquire/release ordering, so the builder's writes are visible to the step that takes
//! the slot and the step's last use happens before the builder's reuse. At most one slot
//! is `Ready` at a time ([`SlotStates::claim`] refuses while one waits). This module holds
//! only the states; the board holds the storage and does the (unsafe) memory access.

use core::sync::atomic::{AtomicU8, Ordering};

/// State of a slot (an unknown code reads as `Free`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, num_enum::FromPrimitive)]
#[repr(u8)]
pub enum SlotState {
    /// Never used, or a build was abandoned: holds no value.
    #[num_enum(default)]
    Free = 0,
    /// The builder owns it and is writing a value.
    Building = 1,
    /// Published: a complete value waits for the step.
    Ready = 2,
    /// The step owns it and uses its value.
    Active = 3,
    /// The step gave it back: holds an old value the builder may drop.
    Retired = 4,
}

/// A slot the builder claimed: its index and whether it holds an old value to drop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Claim {
    /// Index of the slot.
    pub slot: usize,
    /// The slot holds a retired value the builder must drop before writing.
    pub holds_old_value: bool,
}

/// The states of `N` slots.
pub struct SlotStates<const N: usize> {
    states: [AtomicU8; N],
}

impl<const N: usize> Default for SlotStates<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> SlotStates<N> {
    /// All slots free.
    pub const fn new() -> Self {
        Self {
            states: [const { AtomicU8::new(SlotState::Free as u8) }; N],
        }
    }

    /// State of slot `i` now.
    pub fn state(&self, i: usize) -> SlotState {
        self.states.get(i).map_or(SlotState::Free, |s| {
            SlotState::from(s.load(Ordering::Acquire))
        })
    }

    fn swap(&self, i: usize, from: SlotState, to: SlotState) -> bool {
        self.states.get(i).is_some_and(|s| {
            s.compare_exchange(from as u8, to as u8, Ordering::AcqRel, Ordering::Acquire)
                .is_ok()
        })
    }

    /// Builder: a slot to build into (`Free` or `Retired` -> `Building`), or `None` while
    /// a published value still waits for the step or no slot is free.
    pub fn claim(&self) -> Option<Claim> {
        if (0..N).any(|i| self.state(i) == SlotState::Ready) {
            return None;
        }
        (0..N).find_map(|i| {
            if self.swap(i, SlotState::Free, SlotState::Building) {
                Some(Claim {
                    slot: i,
                    holds_old_value: false,
                })
            } else if self.swap(i, SlotState::Retired, SlotState::Building) {
                Some(Claim {
                    slot: i,
                    holds_old_value: true,
                })
            } else {
                None
            }
        })
    }

    /// Builder: the value in `slot` is complete (`Building` -> `Ready`).
    pub fn publish(&self, slot: usize) -> bool {
        self.swap(slot, SlotState::Building, SlotState::Ready)
    }

    /// Builder: the build failed; `slot` holds no value (`Building` -> `Free`).
    pub fn abandon(&self, slot: usize) -> bool {
        self.swap(slot, SlotState::Building, SlotState::Free)
    }

    /// Step: takes the published value, if any (`Ready` -> `Active`).
    pub fn take(&self) -> Option<usize> {
        (0..N).find(|&i| self.swap(i, SlotState::Ready, SlotState::Active))
    }

    /// Step: the slot it uses now, if any.
    pub fn active(&self) -> Option<usize> {
        (0..N).find(|&i| self.state(i) == SlotState::Active)
    }

    /// Step: moved the value out of `slot` (`Active` -> `Free`): nothing left to drop.
    pub fn release(&self, slot: usize) -> bool {
        self.swap(slot, SlotState::Active, SlotState::Free)
    }

    /// Step: done with `slot` (`Active` -> `Retired`); the builder may reuse it.
    pub fn retire(&self, slot: usize) -> bool {
        self.swap(slot, SlotState::Active, SlotState::Retired)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_slot_lifecycle() {
        let s = SlotStates::<1>::new();
        assert_eq!(s.take(), None);
        let c = s.claim().unwrap();
        assert_eq!(
            c,
            Claim {
                slot: 0,
                holds_old_value: false
            }
        );
        assert_eq!(s.claim(), None, "the only slot is being built");
        assert_eq!(s.take(), None, "not published yet");
        assert!(s.publish(0));
        assert!(!s.publish(0));
        assert_eq!(s.take(), Some(0));
        assert_eq!(s.active(), Some(0));
        assert!(s.retire(0));
        assert_eq!(
            s.claim(),
            Some(Claim {
                slot: 0,
                holds_old_value: true
            })
        );
        assert!(s.abandon(0));
        assert_eq!(s.state(0), SlotState::Free);
    }

    #[test]
    fn a_value_moved_out_frees_its_slot_with_nothing_to_drop() {
        let s = SlotStates::<1>::new();
        let a = s.claim().unwrap().slot;
        s.publish(a);
        assert_eq!(s.take(), Some(a));
        assert!(s.release(a));
        assert!(!s.release(a), "only an active slot is released");
        assert_eq!(s.state(a), SlotState::Free);
        assert_eq!(
            s.claim(),
            Some(Claim {
                slot: a,
                holds_old_value: false
            })
        );
    }

    #[test]
    fn a_second_value_waits_until_the_first_is_taken() {
        let s = SlotStates::<2>::new();
        let a = s.claim().unwrap().slot;
        s.publish(a);
        assert_eq!(s.claim(), None);
        assert_eq!(s.take(), Some(a));
        let b = s.claim().unwrap().slot;
        assert_ne!(a, b);
        s.publish(b);
        // The step switches: takes b, gives a back.
        assert_eq!(s.take(), Some(b));
        assert!(s.retire(a));
        assert_eq!(s.active(), Some(b));
        assert_eq!(
            s.claim().map(|c| (c.slot, c.holds_old_value)),
            Some((a, true))
        );
    }
}
