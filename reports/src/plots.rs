//! The report's plots, each drawn once for any plotters backend and written as
//! PNG (for the HTML page) and SVG (for papers):
//!
//! - `scatter`: world-model vs MuJoCo mean score per policy, with both CIs as
//!   error bars, the y = x line, a least-squares fit and r/ρ/τ in the caption;
//! - `bars`: both branches per policy with CIs, sorted by MuJoCo score;
//! - `bump`: each policy's rank under MuJoCo (left) and the world model (right).
//!
//! Text uses the bundled DejaVu Sans, so plots render identically on a machine
//! without any system fonts.

use std::path::{Path, PathBuf};
use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

use crate::labels::{self, Rect};
use crate::summary::Summary;

static FONT: Once = Once::new();

/// Registers the bundled font as "sans-serif" (idempotent).
pub fn register_fonts() {
    FONT.call_once(|| {
        // The font is compiled in and valid; a failure would only lose text, never panic.
        let _ = register_font("sans-serif", FontStyle::Normal, include_bytes!("../fonts/DejaVuSans.ttf"));
    });
}

/// What a drawing backend (or the file system under it) reported.
pub type DrawError = Box<dyn std::error::Error + Send + Sync>;

/// A plotting failure, naming the file.
#[derive(Debug, thiserror::Error)]
#[error("{}: {source}", path.display())]
pub struct PlotError {
    /// The file.
    pub path: PathBuf,
    /// What failed.
    pub source: DrawError,
}

const SIM: RGBColor = RGBColor(31, 119, 180);
const WM: RGBColor = RGBColor(214, 39, 40);

type Res = Result<(), DrawError>;

/// A backend's error, kept as the plot's error source (its message reads `Drawing backend
/// error: …`).
fn e<T: std::error::Error + Send + Sync + 'static>(x: T) -> DrawError {
    Box::new(x)
}

/// Least-squares line y = a + b x (None for fewer than 2 distinct x).
pub fn least_squares(pts: &[(f64, f64)]) -> Option<(f64, f64)> {
    let n = pts.len() as f64;
    let (mx, my) = (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    if pts.len() < 2 || sxx <= 0.0 {
        return None;
    }
    let b = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>() / sxx;
    Some((my - b * mx, b))
}

/// The series legend, upper left, in the house style.
fn legend<'a, DB: DrawingBackend<ErrorType: 'static> + 'a, CT: plotters::coord::CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
) -> Res {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK.mix(0.3))
        .label_font(("sans-serif", 12))
        .draw()
        .map_err(e)
}

fn caption(s: &Summary) -> String {
    let f = |x: Option<crate::summary::Est>| x.map_or("n/a".into(), |v| v.fmt(2));
    format!("r = {}   ρ = {}   τ = {}", f(s.pearson), f(s.spearman), f(s.kendall))
}

fn scatter<DB: DrawingBackend<ErrorType: 'static>>(root: &DrawingArea<DB, Shift>, s: &Summary) -> Res {
    root.fill(&WHITE).map_err(e)?;
    let mut chart = ChartBuilder::on(root)
        .caption(caption(s), ("sans-serif", 16))
        .margin(16)
        .x_label_area_size(44)
        .y_label_area_size(54)
        .build_cartesian_2d(0f64..1f64, 0f64..1f64)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(format!("{} score (mean over episodes)", s.simulator))
        .y_desc("World-model score")
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 14))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(e)?;
    let diag = DashedLineSeries::new(vec![(0.0, 0.0), (1.0, 1.0)], 6, 4, BLACK.mix(0.5).stroke_width(1));
    chart
        .draw_series(diag)
        .map_err(e)?
        .label("y = x")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], BLACK.mix(0.5)));
    let pts: Vec<(f64, f64)> =
        s.policies.iter().map(|p| (p.sim.mean.value, p.world_model.mean.value)).collect();
    if let Some((a, b)) = least_squares(&pts) {
        // Over the data's x range only, clipped to the unit square.
        let (lo, hi) = pts.iter().fold((1.0f64, 0.0f64), |(l, h), p| (l.min(p.0), h.max(p.0)));
        let line = LineSeries::new(
            (0..=50)
                .map(|i| lo + (hi - lo) * f64::from(i) / 50.0)
                .map(|x| (x, a + b * x))
                .filter(|p| (0.0..=1.0).contains(&p.1)),
            WM.mix(0.6).stroke_width(2),
        );
        chart
            .draw_series(line)
            .map_err(e)?
            .label(format!("least squares: y = {a:.2} + {b:.2} x"))
            .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], WM.mix(0.6).stroke_width(2)));
    }
    for p in &s.policies {
        let (x, y) = (p.sim.mean.value, p.world_model.mean.value);
        let style = SIM.stroke_width(1);
        if let Some([lo, hi]) = p.world_model.mean.ci {
            chart.draw_series([ErrorBar::new_vertical(x, lo, y, hi, style, 6)]).map_err(e)?;
        }
        if let Some([lo, hi]) = p.sim.mean.ci {
            chart.draw_series([ErrorBar::new_horizontal(y, lo, x, hi, style, 6)]).map_err(e)?;
        }
        chart.draw_series([Circle::new((x, y), 4, SIM.filled())]).map_err(e)?;
    }
    point_labels(root, &chart, s)?;
    legend(&mut chart)?;
    root.present().map_err(e)
}

/// The policies' names beside their points, placed so that they never overprint
/// (see [`crate::labels`]); a label moved away from its point gets a leader line.
fn point_labels<DB: DrawingBackend<ErrorType: 'static>>(
    root: &DrawingArea<DB, Shift>,
    chart: &ChartContext<
        '_,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
    s: &Summary,
) -> Res {
    let font: TextStyle = ("sans-serif", 12).into();
    let (bx, by) = root.get_base_pixel();
    let (xr, yr) = chart.plotting_area().get_pixel_range();
    let area = Rect { x: xr.start - bx, y: yr.start - by, w: xr.end - xr.start, h: yr.end - yr.start };
    let points: Vec<(i32, i32)> = s
        .policies
        .iter()
        .map(|p| chart.backend_coord(&(p.sim.mean.value, p.world_model.mean.value)))
        .map(|(x, y)| (x - bx, y - by))
        .collect();
    let sizes = s
        .policies
        .iter()
        .map(|p| root.estimate_text_size(&p.name, &font).map(|(w, h)| (w as i32, h as i32)))
        .collect::<Result<Vec<_>, _>>()
        .map_err(e)?;
    for ((p, &(px, py)), l) in s.policies.iter().zip(&points).zip(labels::place(&points, &sizes, area)) {
        let r = l.rect;
        if l.leader {
            // From the point to the nearer vertical edge of the label, at its middle.
            let ex = if r.x > px { r.x - 1 } else { r.x + r.w + 1 };
            root.draw(&PathElement::new([(px, py), (ex, r.y + r.h / 2)], BLACK.mix(0.4))).map_err(e)?;
        }
        root.draw(&Text::new(p.name.clone(), (r.x, r.y), font.clone())).map_err(e)?;
    }
    Ok(())
}

/// Policy indices sorted by MuJoCo mean score, ascending.
fn by_sim(s: &Summary) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..s.policies.len()).collect();
    idx.sort_by(|&a, &b| s.policies[a].sim.mean.value.total_cmp(&s.policies[b].sim.mean.value));
    idx
}

fn bars<DB: DrawingBackend<ErrorType: 'static>>(root: &DrawingArea<DB, Shift>, s: &Summary) -> Res {
    root.fill(&WHITE).map_err(e)?;
    let order = by_sim(s);
    let n = order.len().max(1);
    let names: Vec<String> = order.iter().map(|&i| s.policies[i].name.clone()).collect();
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!("Mean score per policy (95% CIs), sorted by {} score", s.simulator),
            ("sans-serif", 16),
        )
        .margin(16)
        .x_label_area_size(44)
        .y_label_area_size(54)
        .build_cartesian_2d(-0.5f64..(n as f64 - 0.5), 0f64..1.05f64)
        .map_err(e)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(n)
        .x_label_formatter(&|x| names.get(x.round().max(0.0) as usize).cloned().unwrap_or_default())
        .y_desc("Score")
        .light_line_style(WHITE.mix(0.0))
        .label_style(("sans-serif", 12))
        .axis_desc_style(("sans-serif", 14))
        .draw()
        .map_err(e)?;
    let w = 0.36;
    for (col, &i) in order.iter().enumerate() {
        let p = &s.policies[i];
        let x = col as f64;
        for (off, b, color) in [(-w / 2.0, &p.sim, SIM), (w / 2.0, &p.world_model, WM)] {
            let (x0, x1) = (x + off - w / 2.0, x + off + w / 2.0);
            chart
                .draw_series([Rectangle::new([(x0, 0.0), (x1, b.mean.value)], color.mix(0.75).filled())])
                .map_err(e)?;
            if let Some([lo, hi]) = b.mean.ci {
                chart
                    .draw_series([ErrorBar::new_vertical(
                        x + off,
                        lo,
                        b.mean.value,
                        hi,
                        BLACK.stroke_width(1),
                        8,
                    )])
                    .map_err(e)?;
            }
        }
    }
    for (label, color) in [(s.simulator.as_str(), SIM), ("World model", WM)] {
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
            .map_err(e)?
            .label(label)
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], color.mix(0.75).filled()));
    }
    legend(&mut chart)?;
    root.present().map_err(e)
}

/// 1-based ranks, best (highest) first.
fn ranks(v: &[f64]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..v.len()).collect();
    idx.sort_by(|&a, &b| v[b].total_cmp(&v[a]));
    let mut r = vec![0; v.len()];
    for (k, &i) in idx.iter().enumerate() {
        r[i] = k + 1;
    }
    r
}

fn bump<DB: DrawingBackend<ErrorType: 'static>>(root: &DrawingArea<DB, Shift>, s: &Summary) -> Res {
    root.fill(&WHITE).map_err(e)?;
    let n = s.policies.len().max(1);
    let sim = ranks(&s.policies.iter().map(|p| p.sim.mean.value).collect::<Vec<_>>());
    let wm = ranks(&s.policies.iter().map(|p| p.world_model.mean.value).collect::<Vec<_>>());
    let mut chart = ChartBuilder::on(root)
        .caption(format!("Rank under {} (left) and the world model (right)", s.simulator), ("sans-serif", 16))
        .margin(16)
        .build_cartesian_2d(-0.8f64..1.8f64, (n as f64 + 0.5)..0.5f64)
        .map_err(e)?;
    for (i, p) in s.policies.iter().enumerate() {
        let (a, b) = (sim[i] as f64, wm[i] as f64);
        let color = if sim[i] == wm[i] { SIM } else { WM };
        chart.draw_series(LineSeries::new([(0.0, a), (1.0, b)], color.stroke_width(2))).map_err(e)?;
        chart
            .draw_series([Circle::new((0.0, a), 5, color.filled()), Circle::new((1.0, b), 5, color.filled())])
            .map_err(e)?;
        let style = ("sans-serif", 12).into_font();
        chart
            .draw_series([Text::new(format!("{} #{}", p.name, sim[i]), (-0.75, a), style.clone())])
            .map_err(e)?;
        chart.draw_series([Text::new(format!("#{} {}", wm[i], p.name), (1.08, b), style)]).map_err(e)?;
    }
    root.present().map_err(e)
}

fn draw<DB: DrawingBackend<ErrorType: 'static>>(
    name: &str,
    root: &DrawingArea<DB, Shift>,
    s: &Summary,
) -> Res {
    match name {
        "scatter" => scatter(root, s),
        "bars" => bars(root, s),
        _ => bump(root, s),
    }
}

/// Writes `dir/{scatter,bars,bump}.{png,svg}`; returns the PNG paths.
///
/// # Errors
/// [`PlotError`] naming the file that failed.
pub fn write_plots(dir: &Path, s: &Summary) -> Result<Vec<PathBuf>, PlotError> {
    register_fonts();
    std::fs::create_dir_all(dir).map_err(|x| PlotError { path: dir.to_path_buf(), source: Box::new(x) })?;
    let mut out = Vec::new();
    for (name, size) in [("scatter", (640, 600)), ("bars", (760, 480)), ("bump", (640, 420))] {
        let err = |path: &Path, source: DrawError| PlotError { path: path.to_path_buf(), source };
        let png = dir.join(format!("{name}.png"));
        draw(name, &BitMapBackend::new(&png, size).into_drawing_area(), s).map_err(|m| err(&png, m))?;
        let svg = dir.join(format!("{name}.svg"));
        draw(name, &SVGBackend::new(&svg, size).into_drawing_area(), s).map_err(|m| err(&svg, m))?;
        out.push(png);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn least_squares_and_ranks() {
        // Points on y = 0.1 + 0.8 x.
        let (a, b) = least_squares(&[(0.0, 0.1), (0.5, 0.5), (1.0, 0.9)]).unwrap();
        assert!((a - 0.1).abs() < 1e-12 && (b - 0.8).abs() < 1e-12);
        assert_eq!(least_squares(&[(0.3, 0.1), (0.3, 0.2)]), None);
        assert_eq!(ranks(&[0.2, 0.9, 0.5]), vec![3, 1, 2]);
    }
}
