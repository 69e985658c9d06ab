//! End to end: campaigns through the library crates, recordings, scenario files, the real areas,
//! any link, a slow link, and the docs' citations (one integration-test binary: each module was a
//! test binary of its own; `common` is what they share).

mod any_link;
mod campaigns;
mod common;
mod docs;
mod fuzz;
mod generator_on_bundled_areas;
mod geojson;
mod real_areas;
mod recordings;
mod scenario_files;
mod slow_link;
mod tidy;
