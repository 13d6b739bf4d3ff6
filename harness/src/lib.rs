//! evalharness core: what every other crate shares, with no burn or MuJoCo in sight.
//!
//! - [`task`] and [`judge`]: the task interface (seeded episodes, action and observation
//!   specs, exact scores) and the judge of imagined frames, which the paired engine drives;
//!   [`scripted`]: a task's scripted behaviours and dataset layout, which the data
//!   commands run for any task;
//! - [`policy`] + [`rng`]: the batched policy interface and the caller-owned noise streams;
//! - [`image`]: PSNR and SSIM as scikit-image computes them on 8-bit frames; [`resize`]:
//!   OpenCV's INTER_LINEAR resize of 8-bit images (bit for bit on reductions);
//! - [`seed`]: deterministic seed derivation (episode RNGs never depend on thread order),
//!   and checked seed ranges;
//! - [`fingerprint`]: content hashes of model folders, checked on resume;
//! - [`metrics`]: agreement metrics between predicted and true policy scores, with CIs;
//! - [`paired_success`]: each policy's seeds counted by success in both branches;
//! - [`results`]: the typed rows and `results.json` of a ranking run, shared by the
//!   commands that write them and the reports that read them;
//! - [`rows`]: `episodes.jsonl` (append, read, resume at whole batches), and
//!   [`summarise`]: per-policy statistics and agreement from the rows;
//! - [`runfile`]: a training run's config, written at the start and read back on resume;
//! - [`driver`]: the loop skeleton every resumable trainer shares (deadline, Ctrl-C,
//!   seconds over sessions, the resumed log, the atomic state file);
//! - [`stop`]: Ctrl-C / SIGTERM as a cooperative stop that trainers poll between steps;
//! - [`zarr`] and [`replay`]: the diffusion_policy / GPC replay-buffer dataset layout.

pub mod blosc;
pub mod checkpoint;
pub mod driver;
pub mod fingerprint;
pub mod image;
pub mod judge;
pub mod metrics;
pub mod paired_success;
pub mod policy;
pub mod provenance;
pub mod replay;
pub mod resize;
pub mod results;
pub mod rng;
pub mod rows;
pub mod runfile;
pub mod scripted;
pub mod seed;
pub mod sessions;
pub mod stop;
pub mod summarise;
pub mod task;
pub mod task_spec;
pub mod zarr;
