//! Zero-order-hold semantics of the sampled-data loop.

use hcc_model::Model;
use hcc_plant::{LoopTiming, Plant, run_zoh};
use nalgebra::{DVector, Vector3};

/// One revolute joint about z carrying a 2 kg point mass at 0.5 m: I = 0.5 kg m²,
/// no gravity, so q̈ = τ / I exactly.
const PENDULUM: &str = r#"<?xml version="1.0"?>
<robot name="one">
  <link name="base"/>
  <link name="arm">
    <inertial>
      <origin xyz="0.5 0 0" rpy="0 0 0"/>
      <mass value="2.0"/>
      <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/>
    </inertial>
  </link>
  <joint name="j" type="continuous">
    <parent link="base"/>
    <child link="arm"/>
    <axis xyz="0 0 1"/>
  </joint>
</robot>"#;

#[test]
fn torque_is_sampled_at_control_instants_and_held() {
    let model = Model::from_urdf_str(PENDULUM, None, "arm", Some(Vector3::zeros())).unwrap();
    let inertia = 0.5;
    let z = DVector::zeros(1);
    let mut plant = Plant::new(model, &z, &z, &z).unwrap();
    let period = 1e-3;
    let timing = LoopTiming {
        control_period_s: period,
        substeps: 10,
        cycles: 50,
    };
    // τ_k = 1 + k: a staircase. Under a zero-order hold the velocity after cycle K is
    // Σ_{k<K} τ_k T / I and the position Σ_{k<K} (q̇_k T + τ_k T² / (2 I)); RK4 is exact
    // for a constant acceleration, so these hold to rounding.
    let mut expected_q = 0.0;
    let mut expected_qd = 0.0;
    let mut seen_t = Vec::new();
    run_zoh(&mut plant, timing, |k, t, q, qd, tau| {
        seen_t.push(t);
        assert!(
            (q[0] - expected_q).abs() < 1e-12,
            "cycle {k}: q {} vs {expected_q}",
            q[0]
        );
        assert!(
            (qd[0] - expected_qd).abs() < 1e-12,
            "cycle {k}: qd {} vs {expected_qd}",
            qd[0]
        );
        tau[0] = 1.0 + k as f64;
        let acc = tau[0] / inertia;
        expected_q += expected_qd * period + 0.5 * acc * period * period;
        expected_qd += acc * period;
        Ok(())
    })
    .unwrap();
    assert_eq!(seen_t.len(), 51);
    for (k, t) in seen_t.iter().enumerate() {
        assert_eq!(*t, k as f64 * period);
    }
    assert_eq!(plant.t(), 50.0 * period);
    // Contrast: a law re-evaluated at every substep would have seen 10× as many calls.
}
