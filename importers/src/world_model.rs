//! `evalharness import world-model`: another codebase's world-model checkpoint as an
//! evalharness world-model folder, written once so that no later command parses the foreign file.
//!
//! The folder holds `config.json` (the model, plus an `import` record), `ema.bpk` (the
//! imported weights, whichever copy was chosen) and `provenance.json` (the source's SHA-256 and
//! step, the command, the commit). It is staged and replaces `--out` only once complete, and it
//! must load as a model before the command reports it.

use crate::error::{Context, ImportCmdError, Result};
use crate::{Invocation, say};
use burn::module::Module;
use serde::Serialize;
use world_model::import::driftworld::{self, ImportRecord, Preset, Weights};
use world_model::model::{WorldModel, WorldModelConfig};

use crate::args::{ImportPreset, ImportWeights, ImportWorldModelArgs, WorldModelFormat};
use runner::command::write_json;
use runner::output::{Inputs, Staged};

/// An imported model's `config.json`.
#[derive(Serialize)]
struct Config<'a> {
    model: &'a WorldModelConfig,
    import: &'a ImportRecord,
}

/// An imported model's `provenance.json`.
#[derive(Serialize)]
struct Provenance<'a> {
    command: String,
    commit: String,
    import: &'a ImportRecord,
}

/// `evalharness import world-model`.
pub fn run(a: &ImportWorldModelArgs, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<()> {
    let WorldModelFormat::Driftworld = a.format;
    let weights = match a.weights {
        ImportWeights::Ema => Weights::Ema,
        ImportWeights::Inner => Weights::Inner,
    };
    let preset = match a.preset {
        ImportPreset::Pusht => Preset::Pusht,
        ImportPreset::Lift => Preset::Lift,
        ImportPreset::Can => Preset::Can,
    };
    let inputs = Inputs::new().add("FILE", &a.file);
    let staged = Staged::new(&a.out, a.force, &inputs)?;
    let sha256 = harness::fingerprint::file(&a.file).with_context(|| format!("{}", a.file.display()))?;
    let m = driftworld::import(&a.file, weights, preset, a.image_size.map(usize::from), sha256)?;
    write_json(&staged.file("config.json"), &Config { model: &m.config, import: &m.record })?;
    let weights_path = staged.file("ema.bpk");
    m.unet
        .save_file(&weights_path)
        .map_err(|e| ImportCmdError::Refused(format!("writing {}: {e}", weights_path.display())))?;
    let command = inv.command_line.clone().join(" ");
    write_json(
        &staged.file("provenance.json"),
        &Provenance { command, commit: inv.commit.clone(), import: &m.record },
    )?;
    let out = staged.commit()?;
    let device = nn::device::selected()?;
    WorldModel::load(&out, &device)
        .with_context(|| format!("{}: the imported model does not load", out.display()))?;
    tracing::info!(
        "imported {} tensors ({} parameters, step {:?}) from {}",
        m.record.tensors,
        m.record.parameters,
        m.record.step,
        a.file.display()
    );
    say!(say, "{}", out.display());
    Ok(())
}
