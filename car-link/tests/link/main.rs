//! car-link from outside: test vectors, round trips, properties, resynchronisation, transports
//! and the client (one integration-test binary: each module was a test binary of its own;
//! `support` is what they share).

mod client;
mod pipelining;
mod properties;
mod resync;
mod round_trip;
mod support;
mod transport;
mod vectors;
