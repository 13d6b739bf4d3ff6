//! `report.html`: one self-contained page (images embedded as data URIs, no
//! external requests) with the headline numbers, the per-policy table, the
//! plots, optional filmstrips, the run configuration and every checkpoint's
//! provenance. Styled for a laptop screen and for printing.

use std::path::PathBuf;

use base64::Engine;

use crate::summary::{Est, Summary};

/// Extra material for the page.
#[derive(Clone, Debug, Default)]
pub struct Extras {
    /// PNG plots (embedded in this order).
    pub plots: Vec<PathBuf>,
    /// Filmstrip PNGs with captions.
    pub filmstrips: Vec<(PathBuf, String)>,
    /// The run's configuration (pretty JSON).
    pub config: String,
    /// (checkpoint, provenance JSON) pairs.
    pub provenance: Vec<(String, String)>,
    /// Timing and other notes, one line each.
    pub notes: Vec<String>,
}

/// Escapes text for HTML.
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

fn img(path: &PathBuf, alt: &str) -> String {
    match std::fs::read(path) {
        Ok(bytes) => format!(
            "<img alt=\"{}\" src=\"data:image/png;base64,{}\">",
            esc(alt),
            base64::engine::general_purpose::STANDARD.encode(bytes)
        ),
        Err(e) => format!(
            "<p class=\"warn\">missing image {}: {}</p>",
            esc(&path.display().to_string()),
            esc(&e.to_string())
        ),
    }
}

fn est(e: Option<Est>) -> String {
    e.map_or("n/a".into(), |e| e.fmt(3))
}

const STYLE: &str = "body{font-family:'DejaVu Sans',Helvetica,Arial,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222;line-height:1.4}
h1{font-size:1.6em;margin-bottom:.2em}h2{font-size:1.25em;border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}
.sub{color:#666;margin-top:0}.cards{display:flex;flex-wrap:wrap;gap:.8em}.card{border:1px solid #ddd;border-radius:6px;padding:.6em .9em;min-width:140px}
.card b{display:block;font-size:1.35em}.card span{color:#666;font-size:.85em}
table{border-collapse:collapse;width:100%;font-size:.92em}th,td{border-bottom:1px solid #e4e4e4;padding:.35em .5em;text-align:right}th:first-child,td:first-child{text-align:left}
thead th{border-bottom:2px solid #999}.plots{display:flex;flex-wrap:wrap;gap:1em}.plots img{max-width:100%;border:1px solid #eee}
figure{margin:0 0 1em 0}figcaption{color:#555;font-size:.88em}.strip img{width:100%;max-width:960px;image-rendering:pixelated}
pre{background:#f7f7f7;padding:.7em;overflow-x:auto;font-size:.8em}details{margin:.4em 0}.warn{color:#b00}
@media print{body{max-width:none;margin:0}h2{page-break-after:avoid}figure,table{page-break-inside:avoid}details{display:block}pre{white-space:pre-wrap}}";

/// Renders the page.
pub fn report_html(s: &Summary, x: &Extras) -> String {
    let mut h = String::with_capacity(1 << 20);
    h.push_str("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">");
    h.push_str("<meta name=\"viewport\" content=\"width=device-width,initial-scale=1\">");
    h.push_str(&format!(
        "<title>evalharness rank: {}</title><style>{STYLE}</style></head><body>\n",
        esc(&s.scenario)
    ));
    h.push_str(&format!(
        "<h1>Policy ranking: world model vs {}</h1><p class=\"sub\">scenario <b>{}</b> · world model <code>{}</code> · {} policies × {} episodes (seeds {}–{}) · 95% CIs</p>\n",
        esc(&s.simulator),
        esc(&s.scenario),
        esc(&s.world_model),
        s.policies.len(),
        s.episodes,
        s.seed_start,
        s.seed_start + s.episodes.saturating_sub(1)
    ));
    h.push_str("<div class=\"cards\">");
    for (label, e, d) in s.metrics() {
        let (v, ci) = match e {
            Some(Est { value, ci: Some([a, b]) }) => (format!("{value:.d$}"), format!("[{a:.d$}, {b:.d$}]")),
            Some(Est { value, ci: None }) => (format!("{value:.d$}"), String::new()),
            None => ("n/a".into(), String::new()),
        };
        h.push_str(&format!(
            "<div class=\"card\"><span>{}</span><b>{v}</b><span>{ci}</span></div>",
            esc(label)
        ));
    }
    h.push_str("</div>\n");
    if let Some(c) = &s.ceiling {
        h.push_str(&format!(
            "<p class=\"sub\">Noise ceiling: two {} runs of this size (resampled from this one) agree at Pearson {}, {:.1} inversions, mean absolute error {:.3}: the most a world model can reach with this many episodes.</p>\n",
            esc(&s.simulator),
            c.pearson_text(),
            c.rank_inversions,
            c.mean_abs_error
        ));
    }
    if !s.failed.is_empty() {
        h.push_str("<h2>Failed policies</h2><ul>");
        for (p, e) in &s.failed {
            h.push_str(&format!("<li class=\"warn\"><b>{}</b>: {}</li>", esc(p), esc(e)));
        }
        h.push_str("</ul>\n");
    }
    h.push_str(&format!("<h2>Scores per policy</h2><table><thead><tr><th>Policy</th><th>{sim} score</th><th>World-model score</th><th>{sim} success</th><th>World-model success</th><th title=\"Seeds that succeed in both branches / only imagined / only in {sim} / in neither, and Cohen's kappa of the two outcomes over the seeds (0: the imagined outcome of a seed says nothing of the real one)\">Same seed: both · imagined only · {sim} only · neither (κ)</th><th>Episodes</th></tr></thead><tbody>\n", sim = esc(&s.simulator)));
    for p in &s.policies {
        let paired = p.paired.map_or_else(
            || "n/a".to_string(),
            |c| {
                let kappa = c.kappa().map_or_else(|| "n/a".to_string(), |k| format!("{k:.2}"));
                format!("{} · {} · {} · {} (κ {kappa})", c.both, c.imagined_only, c.sim_only, c.neither)
            },
        );
        h.push_str(&format!(
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{paired}</td><td>{}</td></tr>\n",
            esc(&p.name),
            est(Some(p.sim.mean)),
            est(Some(p.world_model.mean)),
            est(Some(p.sim.success)),
            est(Some(p.world_model.success)),
            p.episodes
        ));
    }
    h.push_str("</tbody></table>\n<h2>Plots</h2><div class=\"plots\">");
    for p in &x.plots {
        let name = p.file_stem().map_or(String::new(), |n| n.to_string_lossy().into_owned());
        h.push_str(&format!(
            "<figure>{}<figcaption>{}</figcaption></figure>",
            img(p, &name),
            esc(&plot_caption(&name, s))
        ));
    }
    h.push_str("</div>\n");
    if !x.filmstrips.is_empty() {
        h.push_str("<h2>Rollouts side by side</h2>");
        for (p, cap) in &x.filmstrips {
            h.push_str(&format!(
                "<figure class=\"strip\">{}<figcaption>{}</figcaption></figure>",
                img(p, cap),
                esc(cap)
            ));
        }
    }
    if !x.notes.is_empty() {
        h.push_str("<h2>Notes</h2><ul>");
        for n in &x.notes {
            h.push_str(&format!("<li>{}</li>", esc(n)));
        }
        h.push_str("</ul>");
    }
    h.push_str(&format!("<h2>Configuration</h2><pre>{}</pre>\n<h2>Checkpoints</h2>", esc(&x.config)));
    for (name, prov) in &x.provenance {
        h.push_str(&format!("<details><summary>{}</summary><pre>{}</pre></details>", esc(name), esc(prov)));
    }
    h.push_str("\n<p class=\"sub\">Generated by evalharness.</p></body></html>\n");
    h
}

fn plot_caption(name: &str, s: &Summary) -> String {
    match name {
        "scatter" => format!(
            "World-model vs {} mean score per policy with 95% CIs; dashed: y = x; red: least squares. Pearson r = {}, Spearman ρ = {}, Kendall τ_b = {}.",
            s.simulator,
            est(s.pearson),
            est(s.spearman),
            est(s.kendall)
        ),
        "bars" => {
            format!(
                "Mean score of both branches per policy (95% bootstrap CIs), sorted by {} score.",
                s.simulator
            )
        }
        "score_over_time" => format!(
            "Score so far across episodes (mean and 95% band) at the end of each action chunk, per policy; blue {}, red world model.",
            s.simulator
        ),
        "bump" => format!(
            "Ranks under {} and the world model; red lines change rank ({} inversions).",
            s.simulator,
            s.inversions.map_or("n/a".into(), |e| e.fmt(0))
        ),
        other => other.into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn page_is_self_contained_and_escaped() {
        let r = serde_json::json!({
            "scenario": "pusht", "world_model": "<wm>", "episodes": 1, "seed_start": 0,
            "policies": [], "agreement": {}, "failed_policies": [{"policy": "x", "error": "a<b"}],
        });
        let s = Summary::from_results(&crate::summary::fixture(r));
        let html = report_html(&s, &Extras::default());
        assert!(html.contains("&lt;wm&gt;") && html.contains("a&lt;b"));
        assert!(!html.contains("http://") && !html.contains("https://") && !html.contains("src=\"/"));
        assert!(!html.contains("Noise ceiling"), "a run without one shows none");
    }

    #[test]
    fn the_policy_table_counts_seeds_and_the_page_states_the_noise_ceiling() {
        let r = serde_json::json!({
            "scenario": "can", "world_model": "wm", "episodes": 4, "seed_start": 0,
            "policies": [{"name": "a", "sim": {"mean": 0.5, "ci95": null, "success_rate": 0.5},
                "world_model": {"mean": 0.75, "ci95": null, "success_rate": 0.75},
                "paired_success": {"both": 2, "imagined_only": 1, "sim_only": 0, "neither": 1}}],
            "agreement": {"noise_ceiling": {"pearson": 0.9612, "pearson_ci95": [0.9, 0.99],
                "rank_inversions": 1.25, "mean_abs_error": 0.0613, "replicates": 100}},
        });
        let html = report_html(&Summary::from_results(&crate::summary::fixture(r)), &Extras::default());
        // κ: MuJoCo rate 2/4, imagined 3/4; chance 1/2·3/4 + 1/2·1/4 = 1/2; observed 3/4;
        // κ = (3/4 − 1/2) / (1 − 1/2) = 0.5.
        assert!(html.contains("<td>2 · 1 · 0 · 1 (κ 0.50)</td>"), "{html}");
        assert!(
            html.contains("agree at Pearson 0.961 [0.900, 0.990], 1.2 inversions, mean absolute error 0.061"),
            "{html}"
        );
    }
}
