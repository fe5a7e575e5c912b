//! What the algorithms share: the [`Scratch`] buffers of [`Data`], sized once in
//! [`Data::new`], and the checks of the sizes of their inputs.

use super::spatial::BodyInertia;
use crate::{Data, Model, ModelError};
use nalgebra::{DMatrix, DVector, Isometry3, Vector6};

/// Per-body scratch buffers used by the recursive algorithms (sized in `Data::new`).
/// All spatial quantities are world-frame (see the [module documentation]).
///
/// [module documentation]: super
#[derive(Clone, Debug, Default)]
pub struct Scratch {
    /// Motion subspace `S_i` of each joint.
    pub(super) s: Vec<Vector6<f64>>,
    /// Its time derivative `Ṡ_i = v_i × S_i`.
    pub(super) sdot: Vec<Vector6<f64>>,
    /// Velocity-product (bias) acceleration `Σ_{j≤i} Ṡ_j q̇_j` of each body (no gravity).
    pub(super) abias: Vec<Vector6<f64>>,
    /// Accelerations of the RNEA pass.
    pub(super) a: Vec<Vector6<f64>>,
    /// Forces of the RNEA pass.
    pub(super) f: Vec<Vector6<f64>>,
    /// Spatial inertia of each body.
    pub(super) inertia: Vec<BodyInertia>,
    /// Composite inertia `Σ_{k≥i} I_k`.
    pub(super) ic: Vec<BodyInertia>,
    /// `Ic_i S_i`, `Bc_iᵀ S_i`, `Ic_i Ṡ_i + Bc_i S_i` per body (Coriolis matrix, `Bc_i = Σ_{k≥i} B_k`).
    pub(super) ics: Vec<Vector6<f64>>,
    pub(super) bcts: Vec<Vector6<f64>>,
    pub(super) w: Vec<Vector6<f64>>,
    /// (sin q_i, cos q_i) of the revolute joints.
    pub(super) sin_cos: Vec<(f64, f64)>,
    /// `S_k`, `Ic_k S_k` and `Bc_kᵀ S_k` component by component (18 runs of n: element
    /// c of the vector of body k at `c n + k`), for the Coriolis fill down the columns.
    pub(super) by_component: Vec<f64>,
}

impl Data {
    /// Allocates every buffer the algorithms need for `model`.
    pub fn new(model: &Model) -> Data {
        let n = model.nq();
        let v6 = vec![Vector6::zeros(); n];
        let i6 = vec![BodyInertia::default(); n];
        Data {
            o_m_i: vec![Isometry3::identity(); n],
            v: v6.clone(),
            m: DMatrix::zeros(n, n),
            c: DMatrix::zeros(n, n),
            g: DVector::zeros(n),
            nle: DVector::zeros(n),
            tau: DVector::zeros(n),
            qdd: DVector::zeros(n),
            m_chol: DMatrix::zeros(n, n),
            scratch: Scratch {
                s: v6.clone(),
                sdot: v6.clone(),
                abias: v6.clone(),
                a: v6.clone(),
                f: v6.clone(),
                inertia: i6.clone(),
                ic: i6,
                ics: v6.clone(),
                bcts: v6.clone(),
                w: v6,
                sin_cos: vec![(0.0, 1.0); n],
                by_component: vec![0.0; 18 * n],
            },
        }
    }

    /// Number of bodies this workspace was sized for.
    pub fn nq(&self) -> usize {
        self.o_m_i.len()
    }
}

impl Model {
    /// Checks that `q` (and `qd`, `tau` where given) have length [`Model::nq`].
    pub fn check_state(
        &self,
        q: &DVector<f64>,
        qd: Option<&DVector<f64>>,
        tau: Option<&DVector<f64>>,
    ) -> Result<(), ModelError> {
        let n = self.nq();
        let check = |what: &'static str, got: usize| {
            if got == n {
                Ok(())
            } else {
                Err(ModelError::Dimension {
                    what,
                    expected: n,
                    got,
                })
            }
        };
        check("q", q.len())?;
        if let Some(qd) = qd {
            check("qd", qd.len())?;
        }
        if let Some(tau) = tau {
            check("tau", tau.len())?;
        }
        Ok(())
    }
}

pub(super) fn dims_ok(model: &Model, data: &Data, vecs: &[&DVector<f64>]) -> bool {
    let n = model.nq();
    data.nq() == n && data.m.nrows() == n && vecs.iter().all(|v| v.len() == n)
}
