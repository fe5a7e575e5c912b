//! The control cycle allocates nothing after construction: a counting global
//! allocator over 10 000 steps of the Panda's three-level hierarchy.

mod common;
use common::*;
use hcc_control::Controller;
use nalgebra::DVector;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::SeqCst);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::SeqCst);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn ten_thousand_panda_steps_allocate_nothing() {
    let model = panda();
    let q0 = vec![0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8];
    let mut c = Controller::new(&model, panda_spec(&model), &DVector::from_vec(q0.clone()))
        .expect("controller");
    let mut q = q0.clone();
    let qd = vec![0.1, -0.2, 0.15, 0.1, -0.3, 0.2, 0.25];
    let mut bad = [0.0; 7];
    bad[3] = f64::NAN;
    c.step(&q, &qd).expect("warm-up");
    let before = ALLOCS.load(Ordering::SeqCst);
    let mut sum = 0.0;
    for k in 0..10_000 {
        for (qi, vi) in q.iter_mut().zip(&qd) {
            *qi += 1e-4 * vi;
        }
        let out = c.step(&q, &qd).expect("step");
        sum += out.tau[0];
        if k % 1000 == 0 {
            // The rejection path must not allocate either.
            assert!(c.step(&bad, &qd).is_err());
            c.set_goal(0, &[0.4, 0.1, 0.5]).expect("goal");
        }
    }
    let after = ALLOCS.load(Ordering::SeqCst);
    assert!(sum.is_finite());
    assert_eq!(
        after - before,
        0,
        "the control cycle allocated {} times",
        after - before
    );
}
