//! How Lift's and Can's agentview frames are rendered: the few MuJoCo `<visual>` and
//! material settings that decide what a frame costs on a CPU rasteriser (Mesa's
//! llvmpipe), typed so that a scenario TOML can choose another rendering.
//!
//! Two renderings matter. [`Visual::robosuite`] draws robosuite's own frames (its arena
//! files as they are, MuJoCo's 4× multisampling; an offscreen buffer of the frame's size
//! renders the bytes of robosuite's 640 × 480 one): what robomimic's and DriftWorld's models
//! were trained on, and what this project's Lift and Can models were first trained on.
//! [`Visual::cheap`] skips the multisampling and the floor's mirrored pass: a frame costs about
//! a quarter (BENCHMARKS.md, 2026-11-29, "what a robosuite frame costs").
//! [`Visual::no_reflections`] skips only the mirrored pass: a Can step in `collect` costs about
//! 1 / 1.7 of robosuite's (BENCHMARKS.md, 2026-12-03).
//!
//! Each task renders by default what its shipped models read, their frame encoders adapted to it
//! by `evalharness train adapt` (BENCHMARKS.md, 2026-12-03): Lift the cheap rendering, Can the one
//! without reflections (Can's policies did not keep their MuJoCo success on the cheap one, whose
//! missing multisampling changes their decisions; the mirrored pass barely does). A
//! scenario file's `[visual]` ([`VisualPatch`]) changes the settings it names and keeps the
//! task's default for the others. Each setting is benchmarked on its own
//! (`cargo bench -p scenarios --bench robosuite`), with the pixel difference it makes, in
//! BENCHMARKS.md.

use serde::{Deserialize, Serialize};

use crate::error::ScenarioError;

/// The rendering settings of an arm scene (every one written out; a scenario file gives a
/// [`VisualPatch`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Visual {
    /// The offscreen buffer, `<global offwidth offheight>`, pixels (robosuite: 640 × 480;
    /// here 96 × 96 unless set). It must hold the rendered frame; a frame renders into its
    /// corner either way, to the same bytes (a test renders both), and the smaller buffer
    /// is cheaper to clear and resolve (BENCHMARKS.md, 2026-11-29, "what a robosuite frame
    /// costs": 10% of a Lift frame, 3% of a Can frame).
    pub offscreen: [u32; 2],
    /// Multisamples per pixel of the offscreen buffer, `<quality offsamples>` (MuJoCo and
    /// robosuite: 4; llvmpipe renders 1 and 2 as 4).
    pub samples: u32,
    /// The shadow map's side, `<quality shadowsize>` (MuJoCo: 4096).
    pub shadow_size: u32,
    /// Keep the materials' reflectance (robosuite's floor reflects at 0.01); `false` sets
    /// every arena material's reflectance to 0, which skips MuJoCo's mirrored second pass
    /// over the scene.
    pub reflections: bool,
    /// Render frames at this side and upsample them to the observation size with PyTorch's
    /// bilinear interpolation (`align_corners=False`, rounded to bytes), as DriftWorld's
    /// robomimic data brought robomimic's 84² frames to 96² (`render_size = 84`). Absent: render
    /// at the observation size.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub render_size: Option<u32>,
}

/// A scenario file's `[visual]`: the settings it names, each replacing the task's default
/// ([`VisualPatch::over`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VisualPatch {
    /// [`Visual::offscreen`].
    pub offscreen: Option<[u32; 2]>,
    /// [`Visual::samples`].
    pub samples: Option<u32>,
    /// [`Visual::shadow_size`].
    pub shadow_size: Option<u32>,
    /// [`Visual::reflections`].
    pub reflections: Option<bool>,
    /// [`Visual::render_size`].
    pub render_size: Option<u32>,
}

impl VisualPatch {
    /// `base` with the settings this names replaced.
    pub fn over(self, base: Visual) -> Visual {
        Visual {
            offscreen: self.offscreen.unwrap_or(base.offscreen),
            samples: self.samples.unwrap_or(base.samples),
            shadow_size: self.shadow_size.unwrap_or(base.shadow_size),
            reflections: self.reflections.unwrap_or(base.reflections),
            render_size: self.render_size.or(base.render_size),
        }
    }
}

impl Visual {
    /// robosuite's own rendering (MuJoCo's quality defaults, the arena's reflectance), in a
    /// buffer of the frame's size: the bytes robosuite renders.
    pub fn robosuite() -> Self {
        Self { offscreen: [96, 96], samples: 4, shadow_size: 4096, reflections: true, render_size: None }
    }

    /// A recorded configuration of a task that renders (`renders`: Lift, Can) with its rendering
    /// written out: until 2026-12-03 (8a2407e) a configuration left `visual` out when it was
    /// the default, and the default was then robosuite's rendering for both tasks, so such a
    /// record (a dataset's `scenario_config`, a training-data recipe's) gets
    /// [`Visual::robosuite`], which rendered its frames. Any other record is returned as it is.
    pub fn written_out(renders: bool, config: &serde_json::Value) -> serde_json::Value {
        let mut c = config.clone();
        if let Some(map) = c.as_object_mut().filter(|m| renders && !m.contains_key("visual")) {
            map.insert("visual".into(), serde_json::to_value(Self::robosuite()).unwrap_or_default());
        }
        c
    }

    /// robosuite's rendering without multisampling or reflections, about a quarter of its cost
    /// on a CPU renderer. Lift's default.
    pub fn cheap() -> Self {
        Self { samples: 0, reflections: false, ..Self::robosuite() }
    }

    /// robosuite's rendering without the floor's mirrored pass (multisampling kept). Can's
    /// default.
    pub fn no_reflections() -> Self {
        Self { reflections: false, ..Self::robosuite() }
    }

    /// Checks ranges, for `field` of a scenario file.
    ///
    /// # Errors
    /// [`ScenarioError::InvalidField`] naming the setting.
    pub fn validate(&self, path: &std::path::Path) -> Result<(), ScenarioError> {
        let bad = |field: &str, reason: &str| ScenarioError::InvalidField {
            path: path.into(),
            field: format!("visual.{field}"),
            reason: reason.into(),
        };
        if self.offscreen.iter().any(|&s| !(96..=4096).contains(&s)) {
            return Err(bad("offscreen", "each side must be in [96, 4096] (it holds the 96 x 96 frame)"));
        }
        if self.samples > 16 {
            return Err(bad("samples", "must be in [0, 16]"));
        }
        if !(1..=16384).contains(&self.shadow_size) {
            return Err(bad("shadow_size", "must be in [1, 16384]"));
        }
        if self.render_size.is_some_and(|r| !(16..=1024).contains(&r)) {
            return Err(bad("render_size", "must be in [16, 1024]"));
        }
        Ok(())
    }

    /// The `<visual>` element robosuite's global options carry, with these settings
    /// (at the defaults, the element as it always was: MuJoCo's quality defaults unsaid).
    pub fn xml(&self) -> String {
        let [w, h] = self.offscreen;
        if self.samples == 4 && self.shadow_size == 4096 {
            return format!(
                r#"<visual><map znear="0.001"/><global offwidth="{w}" offheight="{h}"/></visual>"#
            );
        }
        format!(
            r#"<visual><map znear="0.001"/><global offwidth="{w}" offheight="{h}"/><quality offsamples="{}" shadowsize="{}"/></visual>"#,
            self.samples, self.shadow_size
        )
    }

    /// An arena file's text with these settings applied to its materials.
    pub fn arena(&self, text: &str) -> String {
        if self.reflections {
            return text.to_string();
        }
        let mut out = String::with_capacity(text.len());
        let mut rest = text;
        while let Some(i) = rest.find("reflectance=\"") {
            let start = i + "reflectance=\"".len();
            out.push_str(&rest[..start]);
            let end = rest[start..].find('"').map_or(rest.len(), |j| start + j);
            out.push('0');
            rest = &rest[end..];
        }
        out.push_str(rest);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_written_before_renderings_were_recorded_was_robosuites() {
        // A Can dataset of 2026-12-02 (no `visual`: robosuite's, the default then) and one of
        // its cheap rendering (written out, as any rendering but the default was).
        let old = serde_json::json!({"max_steps": 400, "init_noise": 0.02});
        let cheap = serde_json::json!({"max_steps": 400, "visual": Visual::cheap()});
        let filled = Visual::written_out(true, &old);
        assert_eq!(filled["visual"], serde_json::to_value(Visual::robosuite()).unwrap());
        assert_eq!(filled["max_steps"], 400);
        assert_eq!(Visual::written_out(true, &cheap), cheap, "a written rendering is kept");
        assert_eq!(Visual::written_out(false, &old), old, "a task that does not render");
        assert_eq!(Visual::written_out(true, &serde_json::Value::Null), serde_json::Value::Null);
    }

    #[test]
    fn robosuites_rendering_is_mujocos_defaults_and_the_cheap_one_drops_samples_and_reflections() {
        // robosuite's: MuJoCo's documented defaults (offsamples 4, shadowsize 4096, so no
        // <quality> element) in an offscreen buffer of the frame's size (robosuite's 640 x 480
        // renders the same bytes).
        let r = Visual::robosuite();
        assert_eq!(r.xml(), r#"<visual><map znear="0.001"/><global offwidth="96" offheight="96"/></visual>"#);
        // The cheap one: the same but for no multisampling and no reflections.
        let v = Visual::cheap();
        assert_eq!(v, Visual { samples: 0, reflections: false, ..r });
        assert!(v.xml().contains(r#"<quality offsamples="0" shadowsize="4096"/>"#), "{}", v.xml());
        let coarse = Visual { shadow_size: 256, ..v };
        assert!(coarse.xml().contains(r#"<quality offsamples="0" shadowsize="256"/>"#), "{}", coarse.xml());
        let xml = r#"<material name="floor" reflectance="0.01"/><material name="legs" reflectance="0.8" shininess="0.8"/>"#;
        assert_eq!(r.arena(xml), xml);
        assert_eq!(
            v.arena(xml),
            r#"<material name="floor" reflectance="0"/><material name="legs" reflectance="0" shininess="0.8"/>"#
        );
        let p = std::path::Path::new("s.toml");
        assert!(
            Visual { offscreen: [64, 64], ..v }
                .validate(p)
                .unwrap_err()
                .to_string()
                .contains("visual.offscreen")
        );
        v.validate(p).unwrap();
        r.validate(p).unwrap();
        let small = Visual { render_size: Some(8), ..v };
        assert!(small.validate(p).unwrap_err().to_string().contains("visual.render_size"));
        // Written out, a rendering says what it is (an absent render size is not written) and
        // reads back the same.
        let text = toml::to_string(&v).unwrap();
        assert!(!text.contains("render_size") && text.contains("samples = 0"), "{text}");
        assert_eq!(toml::from_str::<Visual>(&text).unwrap(), v);
    }

    #[test]
    fn a_scenario_files_visual_replaces_only_the_settings_it_names() {
        // `render_size = 84` over each task's default keeps that default's other settings.
        let patch: VisualPatch = toml::from_str("render_size = 84").unwrap();
        assert_eq!(patch.over(Visual::cheap()), Visual { render_size: Some(84), ..Visual::cheap() });
        assert_eq!(patch.over(Visual::robosuite()), Visual { render_size: Some(84), ..Visual::robosuite() });
        let patch: VisualPatch = toml::from_str("samples = 4\nreflections = true").unwrap();
        assert_eq!(patch.over(Visual::cheap()), Visual::robosuite());
        assert_eq!(VisualPatch::default().over(Visual::cheap()), Visual::cheap());
        let err = toml::from_str::<VisualPatch>("sample = 4").unwrap_err().to_string();
        assert!(err.contains("sample"), "{err}");
    }
}
