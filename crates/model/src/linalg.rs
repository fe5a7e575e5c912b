//! Small in-place dense linear algebra that never allocates (Cholesky, solves, QR, ...).
