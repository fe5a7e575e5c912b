//! The Coriolis matrix C(q, q̇) with Ṁ = C + Cᵀ (Christoffel symbols), by the O(n²)
//! algorithm of Echeandia & Wensing (arXiv 2010.01033) on the composite inertias of
//! the CRBA.

use super::crba::crba_pass;
use super::data::{Scratch, dims_ok};
use super::kinematics::kinematics;
use super::spatial::{BodyInertia, ang, dot6, join, lin, mat3, mul3tv, mul3v, mul33};
use crate::{Data, Model};
use nalgebra::{DVector, Matrix3, Vector3, Vector6};

/// Coriolis matrix C(q, q̇) with Ṁ = C + Cᵀ into `data.c`: the Christoffel-symbol
/// factorisation `C_kj = Σ_i Γ_kji q̇_i` (as Pinocchio's computeCoriolisMatrix), by the
/// O(n²) algorithm of Echeandia & Wensing (arXiv 2010.01033). Also computes M, the
/// placements and velocities.
pub fn coriolis_matrix(model: &Model, data: &mut Data, q: &DVector<f64>, qd: &DVector<f64>) {
    if !dims_ok(model, data, &[q, qd]) {
        data.c.fill(f64::NAN);
        return;
    }
    kinematics(model, data, q, Some(qd));
    crba_pass(model, data);
    coriolis_pass(model, data);
}

/// Coriolis matrix after [`kinematics`] with velocities and [`crba_pass`]:
/// `C = Σ_i J_iᵀ (I_i J̇_i + B_i J_i)` (Echeandia & Wensing, arXiv 2010.01033,
/// eq. 14–16), where `J_i` holds the world motion subspaces `S_j` (j ≤ i) of the
/// ancestors of body i. On a chain the sum over bodies becomes composite sums:
/// `C[k, j] = (Ic_k S_k)ᵀ Ṡ_j + (Bc_kᵀ S_k)ᵀ S_j` for k ≥ j and
/// `C[k, j] = S_kᵀ (Ic_j Ṡ_j + Bc_j S_j)` for k < j. O(n²).
pub(super) fn coriolis_pass(model: &Model, data: &mut Data) {
    let n = model.nq();
    let sc = &mut data.scratch;
    // Composite B_c = Σ_{k≥i} B_k = [[0, −f_c×], [0, br_c]] (see `coriolis_blocks`).
    let mut f_c = Vector3::zeros();
    let mut br_c = Matrix3::zeros();
    for i in (0..n).rev() {
        let (f, br) = coriolis_blocks(&data.v[i], &sc.inertia[i]);
        f_c += f;
        br_c += br;
        let (sl, sa) = (lin(&sc.s[i]), ang(&sc.s[i]));
        // B_cᵀ S_i and I_c Ṡ_i + B_c S_i.
        sc.bcts[i] = join(Vector3::zeros(), f_c.cross(&sl) + mul3tv(&br_c, &sa));
        sc.w[i] = sc.ic[i].mul(&sc.sdot[i]) + join(-f_c.cross(&sa), mul3v(&br_c, &sa));
    }
    assert_eq!(data.c.shape(), (n, n));
    if n < COMPONENT_FILL_MIN {
        // Column j of C (contiguous) from the per-joint vectors, sliced to n once.
        let (s, sdot, ics, bcts, w) = (
            &sc.s[..n],
            &sc.sdot[..n],
            &sc.ics[..n],
            &sc.bcts[..n],
            &sc.w[..n],
        );
        for (j, col) in data.c.as_mut_slice().chunks_exact_mut(n).enumerate() {
            let (col, sj, sdj, wj) = (&mut col[..n], &s[j], &sdot[j], &w[j]);
            for (k, ck) in col.iter_mut().enumerate() {
                *ck = if k >= j {
                    dot6(&ics[k], sdj) + dot6(&bcts[k], sj)
                } else {
                    dot6(&s[k], wj)
                };
            }
        }
        return;
    }
    assert_eq!(sc.by_component.len(), 18 * n);
    for (c, run) in sc.by_component.chunks_exact_mut(n).enumerate() {
        let (v, c) = match c / 6 {
            0 => (&sc.s, c),
            1 => (&sc.ics, c - 6),
            _ => (&sc.bcts, c - 12),
        };
        for (x, vk) in run.iter_mut().zip(v) {
            *x = vk[c];
        }
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (just checked).
        unsafe { coriolis_fill_avx2(data.c.as_mut_slice(), sc, n) };
        return;
    }
    coriolis_fill(data.c.as_mut_slice(), sc, n);
}

/// The Coriolis operator `B(v) = ½ (v×* I − I v× + (I v)×̄)` of Echeandia & Wensing,
/// "Numerical Methods to Compute the Coriolis Matrix and Christoffel Symbols for
/// Rigid-Body Systems" (arXiv 2010.01033, eq. 13), where `(h)×̄` is the operator
/// `m ↦ m ×* h`; it satisfies `B + Bᵀ = İ` and `B v = v ×* (I v)`.
///
/// Written out with `I = [[m 1, −h×], [h×, I_O]]` and `I v = (f, n)`, the left
/// block column vanishes:
/// `B = [[0, −f×], [0, ½ (2 (v·h) 1 − v hᵀ − h vᵀ + ω× I_O − I_O ω× − n×)]]`.
/// Returns `f` and the lower-right block.
fn coriolis_blocks(v: &Vector6<f64>, inertia: &BodyInertia) -> (Vector3<f64>, Matrix3<f64>) {
    let (vl, w) = (lin(v), ang(v));
    let iv = inertia.mul(v);
    let (f, n) = (lin(&iv), ang(&iv));
    let h = inertia.h;
    let wx = w.cross_matrix();
    let wi = mul33(&wx, &inertia.i_o).data.0;
    let iw = mul33(&inertia.i_o, &wx).data.0;
    let nx = n.cross_matrix().data.0;
    let vh = vl.dot(&h);
    let mut br = [[0.0; 3]; 3];
    for (col, column) in br.iter_mut().enumerate() {
        for (row, x) in column.iter_mut().enumerate() {
            let diag = if row == col { 2.0 * vh } else { 0.0 };
            *x = 0.5
                * (diag - vl[row] * h[col] - h[row] * vl[col] + wi[col][row]
                    - iw[col][row]
                    - nx[col][row]);
        }
    }
    (f, mat3(br))
}

/// The smallest n for which C is filled down its columns by [`coriolis_fill`] (below,
/// the columns are too short to gain from it, and the dot products run directly on the
/// per-joint vectors).
const COMPONENT_FILL_MIN: usize = 8;

/// [`coriolis_fill`] compiled for AVX2 (four rows per instruction; no fused
/// multiply-adds, so the same roundings).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn coriolis_fill_avx2(c: &mut [f64], sc: &Scratch, n: usize) {
    coriolis_fill(c, sc, n);
}

/// C (n × n, column-major `c`) from the per-joint vectors of [`coriolis_pass`], column
/// j down its rows k from the component runs of `S_k`, `Ic_k S_k` and `Bc_kᵀ S_k`, so
/// that consecutive rows are formed side by side in vector registers. Every element
/// is the sum of products of [`dot6`] (`(Ic_k S_k)ᵀ Ṡ_j + (Bc_kᵀ S_k)ᵀ S_j` for k ≥ j,
/// `S_kᵀ w_j` for k < j) in the same order, so C is bitwise that of the dot products.
#[inline(always)]
fn coriolis_fill(c: &mut [f64], sc: &Scratch, n: usize) {
    let by = &sc.by_component[..18 * n];
    let run = |c: usize| &by[c * n..(c + 1) * n];
    let s: [&[f64]; 6] = std::array::from_fn(run);
    let ics: [&[f64]; 6] = std::array::from_fn(|c| run(6 + c));
    let bcts: [&[f64]; 6] = std::array::from_fn(|c| run(12 + c));
    for (j, col) in c[..n * n].chunks_exact_mut(n).enumerate() {
        let (sj, sdj, wj) = (
            &sc.s[j].data.0[0],
            &sc.sdot[j].data.0[0],
            &sc.w[j].data.0[0],
        );
        let (upper, lower) = col.split_at_mut(j);
        // k < j: S_kᵀ w_j.
        for (k, ck) in upper.iter_mut().enumerate() {
            *ck = s[0][k] * wj[0]
                + s[1][k] * wj[1]
                + s[2][k] * wj[2]
                + s[3][k] * wj[3]
                + s[4][k] * wj[4]
                + s[5][k] * wj[5];
        }
        // k ≥ j: (Ic_k S_k)ᵀ Ṡ_j + (Bc_kᵀ S_k)ᵀ S_j.
        for (k, ck) in (j..n).zip(lower.iter_mut()) {
            let a = ics[0][k] * sdj[0]
                + ics[1][k] * sdj[1]
                + ics[2][k] * sdj[2]
                + ics[3][k] * sdj[3]
                + ics[4][k] * sdj[4]
                + ics[5][k] * sdj[5];
            let b = bcts[0][k] * sj[0]
                + bcts[1][k] * sj[1]
                + bcts[2][k] * sj[2]
                + bcts[3][k] * sj[3]
                + bcts[4][k] * sj[4]
                + bcts[5][k] * sj[5];
            *ck = a + b;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compute_all_terms;
    use nalgebra::DMatrix;
    use std::fmt::Write as _;

    /// An n-joint chain (axes alternating z / y / x, offsets and centres of mass off
    /// the axes), long enough for the Coriolis fill by components.
    fn chain(n: usize) -> Model {
        let mut s =
            String::from("<?xml version=\"1.0\"?>\n<robot name=\"c\">\n<link name=\"l0\"/>\n");
        for k in 0..n {
            let axis = ["0 0 1", "0 1 0", "1 0 0"][k % 3];
            let m = 1.0 + 0.1 * k as f64;
            writeln!(
                s,
                "<link name=\"l{}\"><inertial><origin xyz=\"0.01 -0.02 0.05\" rpy=\"0.1 0.2 0.3\"/>\
                 <mass value=\"{m}\"/><inertia ixx=\"0.02\" ixy=\"0.001\" ixz=\"0\" iyy=\"0.025\" \
                 iyz=\"0.002\" izz=\"0.015\"/></inertial></link>\
                 <joint name=\"j{k}\" type=\"revolute\"><parent link=\"l{k}\"/><child link=\"l{}\"/>\
                 <origin xyz=\"0.02 0 0.1\" rpy=\"0 0.1 0\"/><axis xyz=\"{axis}\"/>\
                 <limit lower=\"-3\" upper=\"3\" effort=\"10\" velocity=\"2\"/></joint>",
                k + 1,
                k + 1
            )
            .unwrap();
        }
        s.push_str("</robot>\n");
        Model::from_urdf_str(&s, None, &format!("l{n}"), None).unwrap()
    }

    #[test]
    fn coriolis_fill_by_components_is_bitwise_the_dot_products() {
        for n in [8, 10, 13] {
            let model = chain(n);
            let mut data = Data::new(&model);
            let q = DVector::from_fn(n, |i, _| 0.3 * (i as f64 + 1.0).sin());
            let qd = DVector::from_fn(n, |i, _| 0.5 * (0.7 * i as f64).cos());
            compute_all_terms(&model, &mut data, &q, &qd);
            let sc = &data.scratch;
            let reference = DMatrix::from_fn(n, n, |k, j| {
                if k >= j {
                    dot6(&sc.ics[k], &sc.sdot[j]) + dot6(&sc.bcts[k], &sc.s[j])
                } else {
                    dot6(&sc.s[k], &sc.w[j])
                }
            });
            assert_eq!(data.c, reference, "n = {n}");
            // The portable build as well (the CPUs without AVX2).
            let mut c = DMatrix::zeros(n, n);
            coriolis_fill(c.as_mut_slice(), sc, n);
            assert_eq!(c, reference, "portable, n = {n}");
        }
    }
}
