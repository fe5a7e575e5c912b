//! SO(3) along a path: a rotation R(t) = R_ref exp([r(t)]×) with r(t) a C²
//! rotation vector, its world angular velocity and acceleration,
//!
//! ω = R J_r(r) ṙ,  ω̇ = R (J_r(r) r̈ + J̇_r(r, ṙ) ṙ),
//!
//! with the right Jacobian of SO(3), J_r(r) = I − a(θ) [r]× + b(θ) [r]×²,
//! a = (1 − cos θ)/θ², b = (θ − sin θ)/θ³, θ = ‖r‖ (d/dt exp([r]×) =
//! exp([r]×) [J_r ṙ]×; ω_body = J_r ṙ and d/dt (R ω_body) = R ω̇_body since
//! [ω_body]× ω_body = 0). Series near θ = 0.

use nalgebra::{Matrix3, Vector3};

/// Below this angle a, b and their derivatives come from their series.
const SERIES_ANGLE: f64 = 0.05;

/// a(θ), b(θ), a′(θ)/θ, b′(θ)/θ.
fn coefficients(theta: f64) -> [f64; 4] {
    let t2 = theta * theta;
    if theta < SERIES_ANGLE {
        let t4 = t2 * t2;
        [
            0.5 - t2 / 24.0 + t4 / 720.0,
            1.0 / 6.0 - t2 / 120.0 + t4 / 5040.0,
            -1.0 / 12.0 + t2 / 180.0 - t4 / 6720.0,
            -1.0 / 60.0 + t2 / 1260.0 - t4 / 60480.0,
        ]
    } else {
        let (s, c) = theta.sin_cos();
        let t3 = t2 * theta;
        let t4 = t2 * t2;
        [
            (1.0 - c) / t2,
            (theta - s) / t3,
            (theta * s - 2.0 * (1.0 - c)) / t4,
            (1.0 - c) / t4 - 3.0 * (theta - s) / (t4 * theta),
        ]
    }
}

/// The body angular velocity J_r(r) ṙ and acceleration J_r r̈ + J̇_r ṙ of
/// R_ref exp([r]×) moving with (r, ṙ, r̈).
pub(crate) fn body_rates(
    r: &Vector3<f64>,
    rd: &Vector3<f64>,
    rdd: &Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    let theta = r.norm();
    let [a, b, da, db] = coefficients(theta);
    let rx = r.cross_matrix();
    let rdx = rd.cross_matrix();
    let jr = Matrix3::identity() - rx * a + rx * rx * b;
    let dot = r.dot(rd);
    let jr_dot = -rx * (da * dot) - rdx * a + rx * rx * (db * dot) + (rdx * rx + rx * rdx) * b;
    (jr * rd, jr * rdd + jr_dot * rd)
}

/// The inverse of [`body_rates`]: the rotation vector's rates (ṙ, r̈) at r
/// for the body angular velocity `wb` and acceleration `wdb`,
/// ṙ = J_r⁻¹ ω_b, r̈ = J_r⁻¹ (ω̇_b − J̇_r ṙ); `None` where J_r is singular
/// (‖r‖ a multiple of 2π, beyond any path's turn).
pub(crate) fn coordinate_rates(
    r: &Vector3<f64>,
    wb: &Vector3<f64>,
    wdb: &Vector3<f64>,
) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let [a, b, _, _] = coefficients(r.norm());
    let rx = r.cross_matrix();
    let jr_inv = (Matrix3::identity() - rx * a + rx * rx * b).try_inverse()?;
    let rd = jr_inv * wb;
    let (_, jr_dot_rd) = body_rates(r, &rd, &Vector3::zeros());
    Some((rd, jr_inv * (wdb - jr_dot_rd)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, UnitQuaternion};

    /// ω and ω̇ (world) against central differences of R(t) = R_ref exp(r(t)).
    #[test]
    fn world_rates_match_the_rotation_s_own_derivative() {
        let r_ref = UnitQuaternion::from_euler_angles(0.3, -1.0, 2.0);
        for scale in [1e-4, 0.02, 0.3, 1.5, 2.8] {
            let r_of =
                |t: f64| Vector3::new(0.7 + 0.5 * t, -0.2 + t * t, 0.4 - 0.3 * t * t * t) * scale;
            let rot = |t: f64| r_ref * UnitQuaternion::from_scaled_axis(r_of(t));
            let omega_of = |t: f64| {
                let h = 1e-5;
                let q = rot(t + h) * rot(t - h).inverse();
                q.scaled_axis() / (2.0 * h)
            };
            let t = 0.4;
            let h = 1e-4;
            let rd = (r_of(t + h) - r_of(t - h)) / (2.0 * h);
            let rdd = (r_of(t + h) - 2.0 * r_of(t) + r_of(t - h)) / (h * h);
            let (wb, wdb) = body_rates(&r_of(t), &rd, &rdd);
            let rm: Rotation3<f64> = rot(t).to_rotation_matrix();
            let (w, wd) = (rm * wb, rm * wdb);
            let fd_w = omega_of(t);
            let fd_wd = (omega_of(t + h) - omega_of(t - h)) / (2.0 * h);
            assert!(
                (w - fd_w).norm() < 1e-6 * (1.0 + w.norm()),
                "ω at scale {scale}"
            );
            assert!(
                (wd - fd_wd).norm() < 1e-4 * (1.0 + wd.norm()),
                "ω̇ at scale {scale}: {wd} {fd_wd}"
            );
        }
    }

    #[test]
    fn coordinate_rates_invert_body_rates() {
        for scale in [0.0, 1e-3, 0.04, 0.7, 2.5] {
            let r = Vector3::new(0.3, -0.8, 0.5) * scale;
            let (rd, rdd) = (Vector3::new(0.2, 0.1, -0.4), Vector3::new(-1.0, 0.5, 0.3));
            let (wb, wdb) = body_rates(&r, &rd, &rdd);
            let (rd2, rdd2) = coordinate_rates(&r, &wb, &wdb).unwrap();
            assert!((rd2 - rd).norm() < 1e-12, "ṙ at scale {scale}");
            assert!((rdd2 - rdd).norm() < 1e-12, "r̈ at scale {scale}");
        }
    }

    #[test]
    fn the_series_meets_the_closed_form() {
        let lo = coefficients(SERIES_ANGLE * 0.999_999);
        let hi = coefficients(SERIES_ANGLE * 1.000_001);
        for k in 0..4 {
            assert!(
                (lo[k] - hi[k]).abs() < 1e-9,
                "coefficient {k}: {} {}",
                lo[k],
                hi[k]
            );
        }
    }
}
