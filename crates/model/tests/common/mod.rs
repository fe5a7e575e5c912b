//! Helpers shared by the integration tests of hcc-model.
#![allow(dead_code)]

use hcc_model::Model;
use nalgebra::{DMatrix, DVector, Vector3};
use serde_json::Value;

pub const PANDA_URDF: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../config/robots/panda/panda.urdf"
);
pub const PLANAR_URDF: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/planar4.urdf");
pub const PANDA_JSON: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../tests/data/panda_dynamics.json"
);
pub const PLANAR_JSON: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../tests/data/paper_planar4.json"
);

pub fn panda() -> Model {
    Model::from_urdf_file(PANDA_URDF, None, "panda_hand_tcp", None).unwrap()
}

pub fn planar() -> Model {
    Model::from_urdf_file(
        PLANAR_URDF,
        None,
        "tcp",
        Some(Vector3::new(0.0, -9.81, 0.0)),
    )
    .unwrap()
}

pub fn load_json(path: &str) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

pub fn vec_of(v: &Value) -> DVector<f64> {
    let a = v.as_array().unwrap();
    DVector::from_iterator(a.len(), a.iter().map(|x| x.as_f64().unwrap()))
}

pub fn mat_of(v: &Value) -> DMatrix<f64> {
    let rows = v.as_array().unwrap();
    let ncols = rows[0].as_array().unwrap().len();
    DMatrix::from_row_iterator(
        rows.len(),
        ncols,
        rows.iter()
            .flat_map(|r| r.as_array().unwrap().iter().map(|x| x.as_f64().unwrap())),
    )
}

/// Relative distance used throughout the tests: ‖a − b‖ / max(1, ‖b‖)
/// (Frobenius / Euclidean norms). "Agrees to 1e-9" means this is ≤ 1e-9.
pub fn rel(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    assert_eq!(a.shape(), b.shape());
    (a - b).norm() / b.norm().max(1.0)
}

pub fn relv(a: &DVector<f64>, b: &DVector<f64>) -> f64 {
    assert_eq!(a.len(), b.len());
    (a - b).norm() / b.norm().max(1.0)
}
