//! `evalharness import judge`: another codebase's judge of frames as an evalharness judge
//! folder. GPC's Push-T reward predictors become a `"gpc_pose"` judge: `judge.json` (the source
//! files' SHA-256, the command, the commit) with the two networks, BatchNorms folded, in
//! `xy.bpk` and `angle.bpk`. The folder is staged, replaces `--out` only once complete, and
//! must load before the command reports it.

use crate::error::{Context, Result};
use crate::{Invocation, say};
use judges::folder::{FrameJudge, JudgeFile, Label};
use judges::metrics::JudgeMetrics;
use judges::pose::{import_gpc, write_pose_weights};
use judges::provenance::JudgeProvenance;
use policies::net::NetConfig;
use serde_json::json;

use crate::args::{ImportJudgeArgs, JudgeFormat};
use runner::output::{Inputs, Staged};

/// `evalharness import judge`.
pub fn run(a: &ImportJudgeArgs, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<()> {
    let JudgeFormat::GpcRewardPredictor = a.format;
    let inputs = Inputs::new().add("--xy", &a.xy).add("--angle", &a.angle);
    let staged = Staged::new(&a.out, a.force, &inputs)?;
    let sha = |p: &std::path::Path| harness::fingerprint::file(p).with_context(|| format!("{}", p.display()));
    let (xy_sha, angle_sha) = (sha(&a.xy)?, sha(&a.angle)?);
    let device = nn::device::selected()?;
    let (pose, base) = import_gpc(&a.xy, &a.angle, &device)?;
    let file = JudgeFile {
        kind: "gpc_pose".into(),
        net: NetConfig::new().with_image_size(usize::from(a.image_size)),
        rule: None,
        pose_base: Some(base),
        label: Label::Coverage,
        // GPC's success: coverage above 0.95 (its reward is clip(coverage / 0.95, 0, 1)).
        threshold: 0.95,
        persist_frames: 1,
        steps: 0,
        heldout: JudgeMetrics::default(),
        provenance: JudgeProvenance {
            command: Some(inv.command_line.clone().join(" ")),
            commit: inv.commit.clone(),
            import: Some(json!({
                "format": "gpc-reward-predictor",
                "xy": {"source": a.xy.display().to_string(), "sha256": xy_sha},
                "angle": {"source": a.angle.display().to_string(), "sha256": angle_sha},
                "batchnorm": "folded into the convolutions (eps 1e-5)",
            })),
            ..JudgeProvenance::default()
        },
    };
    write_pose_weights(staged.dir(), &pose)?;
    judges::folder::write_judge(staged.dir(), None, &file)?;
    let out = staged.commit()?;
    FrameJudge::load(&out, &device)
        .with_context(|| format!("{}: the imported judge does not load", out.display()))?;
    say!(say, "{}", out.display());
    Ok(())
}
