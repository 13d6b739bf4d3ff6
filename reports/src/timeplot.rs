//! Score over time: for each policy (one panel each), the mean score so far
//! across episodes at the end of every action chunk, with a 95% band (normal
//! approximation, mean ± 1.96·sd/√n), MuJoCo in blue and the world model in red.
//! Where the red curve leaves the blue band is where imagination drifts.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::plots::{DrawError, PlotError, register_fonts};

/// One policy's curves.
#[derive(Clone, Debug, PartialEq)]
pub struct TimeSeries {
    /// Policy name.
    pub policy: String,
    /// Control step at the end of each chunk.
    pub steps: Vec<f64>,
    /// MuJoCo: (mean, low, high) per chunk.
    pub sim: Vec<[f64; 3]>,
    /// World model: (mean, low, high) per chunk.
    pub world_model: Vec<[f64; 3]>,
}

/// Mean and 95% normal band of each column of equally long traces (shorter traces
/// are ignored past their end).
pub fn band(traces: &[&[f64]]) -> Vec<[f64; 3]> {
    let len = traces.iter().map(|t| t.len()).max().unwrap_or(0);
    (0..len)
        .map(|k| {
            let v: Vec<f64> = traces.iter().filter_map(|t| t.get(k).copied()).collect();
            let n = v.len() as f64;
            let m = v.iter().sum::<f64>() / n;
            let sd = if v.len() > 1 {
                (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
            } else {
                0.0
            };
            let h = 1.959_963_984_540_054 * sd / n.sqrt();
            [m, (m - h).max(0.0), (m + h).min(1.0)]
        })
        .collect()
}

/// A backend's error, kept as the plot's error source.
fn boxed<T: std::error::Error + Send + Sync + 'static>(x: T) -> DrawError {
    Box::new(x)
}

const SIM: RGBColor = RGBColor(31, 119, 180);
const WM: RGBColor = RGBColor(214, 39, 40);

fn panel<DB: DrawingBackend<ErrorType: 'static>>(
    area: &DrawingArea<DB, Shift>,
    ts: &TimeSeries,
    max_step: f64,
) -> Result<(), DrawError> {
    let mut chart = ChartBuilder::on(area)
        .caption(&ts.policy, ("sans-serif", 13))
        .margin(6)
        .margin_right(14)
        .x_label_area_size(26)
        .y_label_area_size(34)
        .build_cartesian_2d(0f64..max_step, 0f64..1f64)
        .map_err(boxed)?;
    chart
        .configure_mesh()
        .x_labels(4)
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_labels(3)
        .light_line_style(WHITE.mix(0.0))
        .label_style(("sans-serif", 10))
        .draw()
        .map_err(boxed)?;
    for (vals, color) in [(&ts.sim, SIM), (&ts.world_model, WM)] {
        let pts = || ts.steps.iter().copied().zip(vals.iter());
        let mut poly: Vec<(f64, f64)> = pts().map(|(x, v)| (x, v[2])).collect();
        poly.extend(pts().rev().map(|(x, v)| (x, v[1])));
        chart.draw_series([Polygon::new(poly, color.mix(0.18).filled())]).map_err(boxed)?;
        chart
            .draw_series(LineSeries::new(pts().map(|(x, v)| (x, v[0])), color.stroke_width(2)))
            .map_err(boxed)?;
    }
    Ok(())
}

fn draw<DB: DrawingBackend<ErrorType: 'static>>(
    root: &DrawingArea<DB, Shift>,
    series: &[TimeSeries],
    simulator: &str,
) -> Result<(), DrawError> {
    root.fill(&WHITE).map_err(boxed)?;
    let (title, body) = root.split_vertically(34);
    title
        .draw(&Text::new(
            format!("Score so far (mean, 95% band) vs control step — blue: {simulator}, red: world model"),
            (10, 8),
            ("sans-serif", 15),
        ))
        .map_err(boxed)?;
    let cols = 4.min(series.len().max(1));
    let rows = series.len().div_ceil(cols).max(1);
    let max_step = series.iter().flat_map(|s| s.steps.iter().copied()).fold(1.0, f64::max);
    for (area, ts) in body.split_evenly((rows, cols)).iter().zip(series) {
        panel(area, ts, max_step)?;
    }
    root.present().map_err(boxed)
}

/// Writes `dir/score_over_time.{png,svg}` (the reference branch named `simulator`); returns
/// the PNG path.
///
/// # Errors
/// [`PlotError`] naming the file.
pub fn write_time_plot(dir: &Path, series: &[TimeSeries], simulator: &str) -> Result<PathBuf, PlotError> {
    register_fonts();
    let cols = 4.min(series.len().max(1)) as u32;
    let rows = series.len().div_ceil(cols as usize).max(1) as u32;
    let size = (240 * cols + 20, 190 * rows + 40);
    let png = dir.join("score_over_time.png");
    let err = |p: &Path, source: DrawError| PlotError { path: p.to_path_buf(), source };
    draw(&BitMapBackend::new(&png, size).into_drawing_area(), series, simulator).map_err(|m| err(&png, m))?;
    let svg = dir.join("score_over_time.svg");
    draw(&SVGBackend::new(&svg, size).into_drawing_area(), series, simulator).map_err(|m| err(&svg, m))?;
    Ok(png)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn band_of_two_traces() {
        // Column 0: (0.2, 0.4): mean 0.3, sd = √0.02 = 0.1414, half width 1.96·0.1414/√2 = 0.196.
        let b = band(&[&[0.2, 0.5], &[0.4, 0.5]]);
        assert!(
            (b[0][0] - 0.3).abs() < 1e-12 && (b[0][1] - 0.104).abs() < 1e-3 && (b[0][2] - 0.496).abs() < 1e-3
        );
        assert_eq!(b[1], [0.5, 0.5, 0.5]);
    }

    /// A plot that cannot be written names its file and keeps the backend's error as its
    /// source (a string before, which lost it).
    #[test]
    fn an_unwritable_plot_names_its_file_and_keeps_the_cause() {
        let dir = tempfile::tempdir().unwrap();
        let not_a_dir = dir.path().join("file");
        std::fs::write(&not_a_dir, b"x").unwrap();
        let ts = TimeSeries {
            policy: "p".into(),
            steps: vec![8.0, 16.0],
            sim: vec![[0.2, 0.1, 0.3]; 2],
            world_model: vec![[0.3, 0.2, 0.4]; 2],
        };
        let e = write_time_plot(&not_a_dir, &[ts], "MuJoCo").unwrap_err();
        assert!(e.to_string().contains("score_over_time.png"), "{e}");
        assert!(std::error::Error::source(&e).is_some());
    }
}
