//! End-to-end tests of drivecheck live in `tests/tests/`; this library only hosts shared helpers.
