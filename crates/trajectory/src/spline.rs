//! One coordinate's C² interpolant through knots (t_k, y_k): a clamped cubic
//! spline (zero velocity at both ends; its second derivatives M_k from the
//! tridiagonal system, solved by the Thomas algorithm) gives each interior
//! knot a velocity and an acceleration; each segment is then the quintic
//! Hermite polynomial through the position, velocity and acceleration at its
//! two knots, with velocity and acceleration zero at the first and the last
//! knot. Inside, the quintic through the cubic's values at both ends is that
//! cubic (the Hermite interpolant is unique); the two end segments start and
//! end at rest, so holding the last knot afterwards keeps ẍ continuous.

/// The coefficients c_0 … c_5 of one segment in s = (t − t_k)/h_k.
pub(crate) type Quintic = [f64; 6];

/// The segments' coefficients of the interpolant through `y` at `t`
/// (t strictly increasing, at least two knots).
pub(crate) fn segments(t: &[f64], y: &[f64]) -> Vec<Quintic> {
    let n = t.len();
    debug_assert!(n >= 2 && y.len() == n);
    let h: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let slope: Vec<f64> = (0..n - 1).map(|k| (y[k + 1] - y[k]) / h[k]).collect();
    // Clamped cubic spline: second derivatives M from
    // h_{k−1} M_{k−1} + 2 (h_{k−1} + h_k) M_k + h_k M_{k+1} = 6 (s_k − s_{k−1}),
    // with S'(t_0) = S'(t_N) = 0 at the ends.
    let mut diag = vec![0.0; n];
    let mut upper = vec![0.0; n];
    let mut lower = vec![0.0; n];
    let mut rhs = vec![0.0; n];
    diag[0] = 2.0 * h[0];
    upper[0] = h[0];
    rhs[0] = 6.0 * slope[0];
    for k in 1..n - 1 {
        lower[k] = h[k - 1];
        diag[k] = 2.0 * (h[k - 1] + h[k]);
        upper[k] = h[k];
        rhs[k] = 6.0 * (slope[k] - slope[k - 1]);
    }
    lower[n - 1] = h[n - 2];
    diag[n - 1] = 2.0 * h[n - 2];
    rhs[n - 1] = -6.0 * slope[n - 2];
    for k in 1..n {
        let w = lower[k] / diag[k - 1];
        diag[k] -= w * upper[k - 1];
        rhs[k] -= w * rhs[k - 1];
    }
    let mut m2 = vec![0.0; n];
    m2[n - 1] = rhs[n - 1] / diag[n - 1];
    for k in (0..n - 1).rev() {
        m2[k] = (rhs[k] - upper[k] * m2[k + 1]) / diag[k];
    }
    // The knots' velocities and accelerations; rest at both ends.
    let mut v = vec![0.0; n];
    let mut a = m2;
    for k in 1..n - 1 {
        v[k] = slope[k] - h[k] * (2.0 * a[k] + a[k + 1]) / 6.0;
    }
    a[0] = 0.0;
    a[n - 1] = 0.0;
    (0..n - 1)
        .map(|k| hermite(h[k], [y[k], v[k], a[k]], [y[k + 1], v[k + 1], a[k + 1]]))
        .collect()
}

/// The quintic in s ∈ [0, 1] with position, velocity, acceleration `p0` at
/// s = 0 and `p1` at s = 1 over a segment of `h` s.
pub(crate) fn hermite(h: f64, p0: [f64; 3], p1: [f64; 3]) -> Quintic {
    let c0 = p0[0];
    let c1 = p0[1] * h;
    let c2 = 0.5 * p0[2] * h * h;
    let r0 = p1[0] - (c0 + c1 + c2);
    let r1 = p1[1] * h - (c1 + 2.0 * c2);
    let r2 = p1[2] * h * h - 2.0 * c2;
    [
        c0,
        c1,
        c2,
        10.0 * r0 - 4.0 * r1 + 0.5 * r2,
        -15.0 * r0 + 7.0 * r1 - r2,
        6.0 * r0 - 3.0 * r1 + 0.5 * r2,
    ]
}

/// Position, velocity and acceleration of segment `c` (length `h` s) at s.
pub(crate) fn evaluate(c: &Quintic, h: f64, s: f64) -> [f64; 3] {
    let p = c[0] + s * (c[1] + s * (c[2] + s * (c[3] + s * (c[4] + s * c[5]))));
    let dp = c[1] + s * (2.0 * c[2] + s * (3.0 * c[3] + s * (4.0 * c[4] + s * 5.0 * c[5])));
    let ddp = 2.0 * c[2] + s * (6.0 * c[3] + s * (12.0 * c[4] + s * 20.0 * c[5]));
    [p, dp / h, ddp / (h * h)]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Position, velocity, acceleration at t of the interpolant.
    fn at(t: &[f64], seg: &[Quintic], x: f64) -> [f64; 3] {
        let k = t.partition_point(|&tk| tk <= x).clamp(1, t.len() - 1) - 1;
        let h = t[k + 1] - t[k];
        evaluate(&seg[k], h, (x - t[k]) / h)
    }

    #[test]
    fn passes_the_knots_is_c2_across_them_and_starts_and_ends_at_rest() {
        let t = [0.0, 0.3, 0.5, 1.2, 1.3, 2.0];
        let y = [0.0, 0.4, -0.1, 0.2, 0.25, 1.0];
        let seg = segments(&t, &y);
        for (k, (&tk, &yk)) in t.iter().zip(&y).enumerate() {
            assert!((at(&t, &seg, tk)[0] - yk).abs() < 1e-12, "knot {k}");
        }
        for &tk in &t[1..t.len() - 1] {
            let (l, r) = (at(&t, &seg, tk - 1e-9), at(&t, &seg, tk + 1e-9));
            for d in 0..3 {
                assert!(
                    (l[d] - r[d]).abs() < 1e-5 * (1.0 + l[d].abs()),
                    "C² at {tk}: {l:?} {r:?}"
                );
            }
        }
        for e in [at(&t, &seg, 0.0), at(&t, &seg, 2.0)] {
            assert!(
                e[1].abs() < 1e-12 && e[2].abs() < 1e-12,
                "rest at the ends: {e:?}"
            );
        }
    }

    #[test]
    fn the_derivatives_are_those_of_the_position() {
        let t: Vec<f64> = (0..40).map(|k| k as f64 * 0.05).collect();
        let y: Vec<f64> = t.iter().map(|x| (3.0 * x).sin()).collect();
        let seg = segments(&t, &y);
        let h = 1e-6;
        for k in 1..199 {
            let x = k as f64 * 0.0097;
            let [_, v, a] = at(&t, &seg, x);
            let fd_v = (at(&t, &seg, x + h)[0] - at(&t, &seg, x - h)[0]) / (2.0 * h);
            let fd_a = (at(&t, &seg, x + h)[1] - at(&t, &seg, x - h)[1]) / (2.0 * h);
            assert!(
                (v - fd_v).abs() < 1e-6 && (a - fd_a).abs() < 1e-5,
                "t = {x}"
            );
        }
        // Away from the ends it follows sin(3t) closely (a cubic spline).
        let [p, v, _] = at(&t, &seg, 1.0);
        assert!((p - 3.0f64.sin()).abs() < 1e-4 && (v - 3.0 * 3.0f64.cos()).abs() < 1e-2);
    }
}
