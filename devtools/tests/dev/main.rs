//! `drivecheck-dev` as a developer runs it: each benchmark on a small size (one integration-test
//! binary; `common` is what the modules share).

mod agreement;
mod common;
mod compare;
mod fidelity;
mod placement;
mod scale;
