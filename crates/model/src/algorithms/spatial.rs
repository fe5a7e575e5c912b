//! Spatial-vector algebra in world coordinates at the world origin (RBDA Ch. 2, see
//! the module documentation of [`super`]): the 3×3 products written out, the motion
//! and force cross products, and the world-frame body inertia [`BodyInertia`].

use crate::SpatialInertia;
use nalgebra::{ArrayStorage, Matrix3, Vector3, Vector6};

// 3×3 products written out on the column-major arrays: the same as nalgebra's
// in release builds, and much faster in unoptimised (test) builds.

#[inline]
pub(super) fn mat3(a: [[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::from_array_storage(ArrayStorage(a))
}

/// `a b`.
#[inline]
pub(super) fn mul33(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Matrix3<f64> {
    let (a, b) = (&a.data.0, &b.data.0);
    let mut out = [[0.0; 3]; 3];
    for (col, oc) in out.iter_mut().enumerate() {
        for (row, x) in oc.iter_mut().enumerate() {
            *x = a[0][row] * b[col][0] + a[1][row] * b[col][1] + a[2][row] * b[col][2];
        }
    }
    mat3(out)
}

/// `a bᵀ`.
#[inline]
fn mul33t(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Matrix3<f64> {
    let (a, b) = (&a.data.0, &b.data.0);
    let mut out = [[0.0; 3]; 3];
    for (col, oc) in out.iter_mut().enumerate() {
        for (row, x) in oc.iter_mut().enumerate() {
            *x = a[0][row] * b[0][col] + a[1][row] * b[1][col] + a[2][row] * b[2][col];
        }
    }
    mat3(out)
}

/// `a v`.
#[inline]
pub(super) fn mul3v(a: &Matrix3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
    let a = &a.data.0;
    let v = &v.data.0[0];
    Vector3::new(
        a[0][0] * v[0] + a[1][0] * v[1] + a[2][0] * v[2],
        a[0][1] * v[0] + a[1][1] * v[1] + a[2][1] * v[2],
        a[0][2] * v[0] + a[1][2] * v[1] + a[2][2] * v[2],
    )
}

/// `aᵀ v`.
#[inline]
pub(super) fn mul3tv(a: &Matrix3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
    let a = &a.data.0;
    let v = &v.data.0[0];
    Vector3::new(
        a[0][0] * v[0] + a[0][1] * v[1] + a[0][2] * v[2],
        a[1][0] * v[0] + a[1][1] * v[1] + a[1][2] * v[2],
        a[2][0] * v[0] + a[2][1] * v[1] + a[2][2] * v[2],
    )
}

/// Rotation by the angle θ with (`s`, `c`) = (sin θ, cos θ) about the unit `axis`
/// (Rodrigues' formula, `R = cos θ 1 + sin θ [a]× + (1 − cos θ) a aᵀ`).
#[inline]
pub(super) fn axis_angle(axis: &Vector3<f64>, (s, c): (f64, f64)) -> Matrix3<f64> {
    let a = &axis.data.0[0];
    let t = 1.0 - c;
    mat3([
        [
            c + t * a[0] * a[0],
            t * a[1] * a[0] + s * a[2],
            t * a[2] * a[0] - s * a[1],
        ],
        [
            t * a[0] * a[1] - s * a[2],
            c + t * a[1] * a[1],
            t * a[2] * a[1] + s * a[0],
        ],
        [
            t * a[0] * a[2] + s * a[1],
            t * a[1] * a[2] - s * a[0],
            c + t * a[2] * a[2],
        ],
    ])
}

#[inline]
pub(super) fn lin(v: &Vector6<f64>) -> Vector3<f64> {
    let v = &v.data.0[0];
    Vector3::new(v[0], v[1], v[2])
}

#[inline]
pub(super) fn ang(v: &Vector6<f64>) -> Vector3<f64> {
    let v = &v.data.0[0];
    Vector3::new(v[3], v[4], v[5])
}

/// `aᵀ b` of 6-vectors.
#[inline]
pub(super) fn dot6(a: &Vector6<f64>, b: &Vector6<f64>) -> f64 {
    let (a, b) = (&a.data.0[0], &b.data.0[0]);
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] + a[4] * b[4] + a[5] * b[5]
}

#[inline]
pub(super) fn join(l: Vector3<f64>, a: Vector3<f64>) -> Vector6<f64> {
    Vector6::new(l.x, l.y, l.z, a.x, a.y, a.z)
}

/// Spatial motion cross product `a × b` (RBDA Ch. 2, linear-first order).
#[inline]
pub(super) fn motion_cross(a: &Vector6<f64>, b: &Vector6<f64>) -> Vector6<f64> {
    let (va, wa) = (lin(a), ang(a));
    let (vb, wb) = (lin(b), ang(b));
    join(wa.cross(&vb) + va.cross(&wb), wa.cross(&wb))
}

/// Spatial force cross product `v ×* f` (RBDA Ch. 2, linear-first order).
#[inline]
pub(super) fn force_cross(v: &Vector6<f64>, f: &Vector6<f64>) -> Vector6<f64> {
    let (vv, w) = (lin(v), ang(v));
    let (fl, n) = (lin(f), ang(f));
    join(w.cross(&fl), w.cross(&n) + vv.cross(&fl))
}

/// World-frame spatial inertia in compact form (RBDA Ch. 2, taken at the world
/// origin, linear-first order): the 6×6 matrix `[[m 1, −h×], [h×, I_O]]` with
/// mass `m`, first moment `h = m c` and rotational inertia `I_O = I_c − m c× c×`
/// about the world origin. Composite inertias are plain sums.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct BodyInertia {
    pub(super) m: f64,
    pub(super) h: Vector3<f64>,
    pub(super) i_o: Matrix3<f64>,
}

impl BodyInertia {
    /// The inertia of a body with world rotation `r` and origin `p`.
    #[inline]
    pub(super) fn from_body(
        si: &SpatialInertia,
        r: &Matrix3<f64>,
        p: &Vector3<f64>,
    ) -> BodyInertia {
        let c = p + mul3v(r, &si.com);
        let iw = mul33t(&mul33(r, &si.inertia), r);
        // I_O = I_w + m (|c|² 1 − c cᵀ)
        let m = si.mass;
        let c2 = c.norm_squared();
        let mut i_o = iw.data.0;
        for (col, column) in i_o.iter_mut().enumerate() {
            for (row, x) in column.iter_mut().enumerate() {
                let delta = if row == col { c2 } else { 0.0 };
                *x += m * (delta - c[row] * c[col]);
            }
        }
        BodyInertia {
            m,
            h: c * m,
            i_o: mat3(i_o),
        }
    }

    /// `I (v, ω) = (m v − h × ω, h × v + I_O ω)`.
    #[inline]
    pub(super) fn mul(&self, x: &Vector6<f64>) -> Vector6<f64> {
        let (v, w) = (lin(x), ang(x));
        join(
            v * self.m - self.h.cross(&w),
            self.h.cross(&v) + mul3v(&self.i_o, &w),
        )
    }

    #[inline]
    pub(super) fn add(&mut self, other: &BodyInertia) {
        self.m += other.m;
        self.h += other.h;
        self.i_o += other.i_o;
    }
}
