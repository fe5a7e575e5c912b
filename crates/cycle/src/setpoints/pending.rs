//! Setpoints waiting for the state they are due at.

use hcc_msgs::{MAX_PENDING_SETPOINTS, Setpoint};

/// Setpoints waiting for their state: fixed slots (allocated and written
/// at construction, so the loop neither allocates nor faults pages) and
/// their arrival order.
pub(super) struct Pending {
    pub(super) slots: Box<[Setpoint]>,
    /// Slot indices of the waiting setpoints, in arrival order.
    pub(super) order: [usize; MAX_PENDING_SETPOINTS],
    pub(super) len: usize,
    /// Free slot indices (a stack).
    free: [usize; MAX_PENDING_SETPOINTS],
    free_len: usize,
}

impl Pending {
    pub(super) fn new() -> Pending {
        let mut free = [0; MAX_PENDING_SETPOINTS];
        for (k, f) in free.iter_mut().enumerate() {
            *f = MAX_PENDING_SETPOINTS - 1 - k;
        }
        Pending {
            slots: vec![Setpoint::zeroed(); MAX_PENDING_SETPOINTS].into_boxed_slice(),
            order: [0; MAX_PENDING_SETPOINTS],
            len: 0,
            free,
            free_len: MAX_PENDING_SETPOINTS,
        }
    }

    /// Queues a copy of `sp`; false when every slot is taken.
    pub(super) fn push(&mut self, sp: &Setpoint) -> bool {
        if self.free_len == 0 || self.len == MAX_PENDING_SETPOINTS {
            return false;
        }
        self.free_len -= 1;
        let slot = self.free[self.free_len];
        self.slots[slot] = *sp;
        self.order[self.len] = slot;
        self.len += 1;
        true
    }

    /// Removes the `k`-th waiting setpoint (arrival order) and frees its slot.
    pub(super) fn remove(&mut self, k: usize) {
        let slot = self.order[k];
        self.order.copy_within(k + 1..self.len, k);
        self.len -= 1;
        self.free[self.free_len] = slot;
        self.free_len += 1;
    }
}
