//! evalharness media and reports.
//!
//! So far: animated GIFs of episodes ([`gif`]). Plots, filmstrips, the HTML
//! summary and the LaTeX table of `rank` will live here too.

pub mod gif;
pub mod png;
