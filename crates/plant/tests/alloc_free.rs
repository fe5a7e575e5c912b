//! `Plant::step` and `Plant::energy` must not allocate (real-time use in the
//! simulator daemon). A counting global allocator checks it.

use hcc_model::Model;
use hcc_plant::{ExternalWrench, Plant};
use nalgebra::{DVector, Vector3};

/// Counts the allocations of each thread (`hcc_rtalloc::thread_stats`), so the
/// test harness's own threads never disturb the count.
#[global_allocator]
static GLOBAL: hcc_rtalloc::RtAllocator = hcc_rtalloc::RtAllocator::new();

#[test]
fn step_with_wrench_and_energy_do_not_allocate() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/robots/panda/panda.urdf"
    );
    let model = Model::from_urdf_file(path, None, "panda_hand_tcp", None).unwrap();
    let tcp = model.tip_frame();
    let q0 = DVector::from_column_slice(&[0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8]);
    let z = DVector::zeros(7);
    let f = DVector::from_element(7, 0.1);
    let mut plant = Plant::new(model, &q0, &z, &f).unwrap();
    plant
        .set_wrenches(vec![ExternalWrench {
            start_s: 0.0,
            duration_s: 1.0,
            frame: tcp,
            force: Vector3::new(1.0, 2.0, 3.0),
            torque: Vector3::new(0.1, 0.0, 0.0),
        }])
        .unwrap();
    let tau = DVector::from_element(7, 0.5);
    plant.step(&tau, 1e-4).unwrap();
    let before = hcc_rtalloc::thread_stats().allocs;
    let mut e = 0.0;
    for _ in 0..100 {
        plant.step(&tau, 1e-4).unwrap();
        e += plant.energy().total();
    }
    let after = hcc_rtalloc::thread_stats().allocs;
    assert!(e.is_finite());
    assert_eq!(
        after - before,
        0,
        "{} allocations in 100 steps",
        after - before
    );
}
