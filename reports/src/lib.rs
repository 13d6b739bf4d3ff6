//! evalharness media and reports.
//!
//! - [`gif`], [`png`]: animated GIFs and filmstrips of episodes;
//! - [`episodes`]: the per-episode table as parquet;
//! - [`summary`]: what a `rank` report shows, read from `results.json`;
//! - [`plots`]: scatter, bar and bump charts (PNG + SVG, bundled font);
//! - [`labels`]: scatter-label placement without overprinting;
//! - [`timeplot`]: score over time per policy, both branches;
//! - [`tables`]: the LaTeX table and the summary CSV;
//! - [`html`]: the self-contained HTML report.

pub mod episode_tables;
pub mod episodes;
pub mod gif;
pub mod html;
pub mod labels;
pub mod plots;
pub mod png;
pub mod scene;
pub mod summary;
pub mod tables;
pub mod tasks;
pub mod timeplot;
