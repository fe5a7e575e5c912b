//! Helpers shared by the system tests: locating the built binaries, temporary directories, unique namespaces.
