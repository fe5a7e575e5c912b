//! The loader's context: the scenario file and its text, with the checks of
//! values that every table uses and errors that name the field and its line.

use std::path::Path;

use nalgebra::{DMatrix, DVector};

use crate::error::{ConfigError, invalid};
use crate::values::{GainValue, PerJoint};

/// Loader context: the file, its text, and helpers that build located errors.
#[derive(Clone, Copy)]
pub(crate) struct Ctx<'a> {
    pub(crate) file: &'a Path,
    pub(crate) text: &'a str,
    /// Resolving a level of `[[level.task]]` tables (errors name the table).
    pub(crate) stacked: bool,
    /// Resolving a level that follows a path (`trajectory`: no goal).
    pub(crate) trajectory: bool,
}

impl Ctx<'_> {
    pub(crate) fn err(&self, path: &str, message: impl Into<String>) -> ConfigError {
        invalid(self.file, self.text, path, message)
    }

    pub(crate) fn finite(&self, path: &str, v: &[f64]) -> Result<(), ConfigError> {
        match v.iter().position(|x| !x.is_finite()) {
            Some(k) => Err(self.err(&format!("{path}[{k}]"), "must be a finite number")),
            None => Ok(()),
        }
    }

    pub(crate) fn vector(
        &self,
        path: &str,
        v: &[f64],
        len: usize,
        what: &str,
    ) -> Result<DVector<f64>, ConfigError> {
        if v.len() != len {
            return Err(self.err(
                path,
                format!("has {} elements, expected {len} ({what})", v.len()),
            ));
        }
        self.finite(path, v)?;
        Ok(DVector::from_column_slice(v))
    }

    pub(crate) fn per_joint(
        &self,
        path: &str,
        v: &PerJoint,
        n: usize,
        allow_inf: bool,
    ) -> Result<DVector<f64>, ConfigError> {
        let out = match v {
            PerJoint::Scalar(s) => DVector::from_element(n, *s),
            PerJoint::Vector(v) => {
                if v.len() != n {
                    return Err(self.err(
                        path,
                        format!(
                            "has {} elements, expected {n} (one per joint) or a scalar",
                            v.len()
                        ),
                    ));
                }
                DVector::from_column_slice(v)
            }
        };
        for (k, x) in out.iter().enumerate() {
            let p = match v {
                PerJoint::Scalar(_) => path.to_string(),
                PerJoint::Vector(_) => format!("{path}[{k}]"),
            };
            if x.is_nan() || (!allow_inf && x.is_infinite()) {
                return Err(self.err(&p, "must be a finite number"));
            }
            if *x < 0.0 {
                return Err(self.err(&p, format!("must not be negative, got {x}")));
            }
        }
        Ok(out)
    }

    /// A stiffness or damping matrix of size m: symmetric positive definite.
    pub(crate) fn gain(
        &self,
        path: &str,
        g: &GainValue,
        m: usize,
    ) -> Result<DMatrix<f64>, ConfigError> {
        let mat = match g {
            GainValue::Scalar(s) => DMatrix::from_diagonal_element(m, m, *s),
            GainValue::Diagonal(d) => {
                if d.len() != m {
                    return Err(self.err(
                        path,
                        format!(
                            "has {} diagonal elements, expected {m} (the task dimension)",
                            d.len()
                        ),
                    ));
                }
                DMatrix::from_diagonal(&DVector::from_column_slice(d))
            }
            GainValue::Matrix(rows) => {
                if rows.len() != m || rows.iter().any(|r| r.len() != m) {
                    return Err(self.err(
                        path,
                        format!(
                            "must be a {m}×{m} matrix (the task dimension), a diagonal or a scalar"
                        ),
                    ));
                }
                DMatrix::from_fn(m, m, |i, j| rows[i][j])
            }
        };
        if mat.iter().any(|x| !x.is_finite()) {
            return Err(self.err(path, "must contain finite numbers only"));
        }
        for i in 0..m {
            for j in 0..i {
                let (a, b) = (mat[(i, j)], mat[(j, i)]);
                if (a - b).abs() > 1e-12 * a.abs().max(b.abs()).max(1.0) {
                    return Err(self.err(
                        path,
                        format!("must be symmetric: element ({i},{j}) = {a} but ({j},{i}) = {b}"),
                    ));
                }
            }
        }
        let mut l = mat.clone();
        if hcc_model::linalg::cholesky_in_place(&mut l).is_err() {
            let what = if (0..m).any(|i| mat[(i, i)] < 0.0) {
                "must be positive definite (a diagonal element is negative)"
            } else {
                "must be positive definite"
            };
            return Err(self.err(path, what));
        }
        Ok(mat)
    }
}
