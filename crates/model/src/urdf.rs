//! Building a [`crate::Model`] from a URDF file or string (urdf-rs).
