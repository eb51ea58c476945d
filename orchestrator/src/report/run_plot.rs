//! The plot of `twin run`: one panel per recorded numeric column against time, stacked, the
//! time axis on the bottom panel. Integer, Enumeration and Boolean columns are drawn as steps.

use plotters::prelude::*;

use crate::cosim::import::ScalarType;
use crate::cosim::run::RunResult;

const FONT: &str = "sans-serif";
const LINE: RGBColor = super::palette::BLUE;
/// Panels beyond this many are left out (named in the title).
pub const MAX_PANELS: usize = 16;
const PANEL_HEIGHT: u32 = 160;
const WIDTH: u32 = 1200;

fn text(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// The SVG text of the plot, titled `title`.
pub fn plot_run(result: &RunResult, title: &str) -> Result<String, String> {
    let numeric: Vec<usize> = (0..result.columns.len())
        .filter(|&c| result.columns[c].scalar_type != ScalarType::String)
        .collect();
    if numeric.is_empty() || result.time.is_empty() {
        return Err("nothing numeric was recorded".into());
    }
    let shown = &numeric[..numeric.len().min(MAX_PANELS)];
    let title = if shown.len() < numeric.len() {
        format!(
            "{title} (first {} of {} columns)",
            shown.len(),
            numeric.len()
        )
    } else {
        title.to_owned()
    };
    let (t0, t1) = (
        result.time[0],
        *result.time.last().unwrap_or(&result.time[0]),
    );
    let t1 = if t1 > t0 { t1 } else { t0 + 1.0 };
    let height = 50 + PANEL_HEIGHT * shown.len() as u32 + 40;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (WIDTH, height)).into_drawing_area();
        root.fill(&WHITE).map_err(text)?;
        let root = root.titled(&title, (FONT, 22)).map_err(text)?;
        let (panels, _) = root.split_vertically(PANEL_HEIGHT * shown.len() as u32 + 40);
        let areas = panels.split_evenly((shown.len(), 1));
        for (n, (&c, area)) in shown.iter().zip(areas.iter()).enumerate() {
            let values = &result.values[c];
            let (mut lo, mut hi) = values
                .iter()
                .filter(|v| v.is_finite())
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                    (a.min(v), b.max(v))
                });
            if !lo.is_finite() {
                (lo, hi) = (-1.0, 1.0);
            }
            if hi - lo <= f64::EPSILON * lo.abs().max(1.0) {
                (lo, hi) = (lo - 0.5, hi + 0.5);
            }
            let pad = 0.05 * (hi - lo);
            let last = n + 1 == shown.len();
            let mut chart = ChartBuilder::on(area)
                .margin(6)
                .x_label_area_size(if last { 30 } else { 0 })
                .y_label_area_size(70)
                .caption(&result.columns[c].name, (FONT, 15))
                .build_cartesian_2d(t0..t1, (lo - pad)..(hi + pad))
                .map_err(text)?;
            let mut mesh = chart.configure_mesh();
            mesh.y_labels(4).light_line_style(WHITE.mix(0.0));
            if last {
                mesh.x_desc("time (s)");
            } else {
                mesh.disable_x_axis();
            }
            mesh.draw().map_err(text)?;
            let stepped = result.columns[c].scalar_type != ScalarType::Real;
            let mut points: Vec<(f64, f64)> = Vec::with_capacity(values.len() * 2);
            for (k, (&t, &v)) in result.time.iter().zip(values).enumerate() {
                if !v.is_finite() {
                    continue;
                }
                if stepped && k > 0 {
                    if let Some(&(_, previous)) = points.last() {
                        points.push((t, previous));
                    }
                }
                points.push((t, v));
            }
            chart
                .draw_series(LineSeries::new(points, LINE.stroke_width(2)))
                .map_err(text)?;
        }
        root.present().map_err(text)?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cosim::run::Column;

    fn result(names: &[(&str, ScalarType)]) -> RunResult {
        let time: Vec<f64> = (0..50).map(|k| k as f64 * 0.1).collect();
        RunResult {
            columns: names
                .iter()
                .map(|(n, t)| Column {
                    name: (*n).to_owned(),
                    scalar_type: *t,
                })
                .collect(),
            values: names
                .iter()
                .enumerate()
                .map(|(i, _)| time.iter().map(|t| (t * (i + 1) as f64).sin()).collect())
                .collect(),
            time,
            texts: Default::default(),
            start: 0.0,
            stop: 4.9,
            step: 0.1,
            terminated: None,
        }
    }

    #[test]
    fn one_panel_per_numeric_column_with_its_name() {
        let r = result(&[("h", ScalarType::Real), ("bounces", ScalarType::Integer)]);
        let svg = plot_run(&r, "ball").expect("draws");
        assert!(svg.starts_with("<svg") && svg.contains("ball"));
        assert!(
            svg.contains(">\nh\n</text>") && svg.contains(">\nbounces\n</text>"),
            "panel captions"
        );
        // Each series is one polyline through all 50 points (the step drawing doubles them).
        let longest = svg
            .split("<polyline")
            .skip(1)
            .map(|p| {
                p.split("points=\"")
                    .nth(1)
                    .map_or(0, |q| q.split('"').next().unwrap_or("").split(' ').count())
            })
            .max()
            .unwrap_or(0);
        assert!(longest >= 50, "the longest line has {longest} points");
    }

    #[test]
    fn strings_only_cannot_be_plotted() {
        let mut r = result(&[("label", ScalarType::String)]);
        r.texts.insert(0, vec![String::new(); 50]);
        assert!(plot_run(&r, "x").is_err());
    }
}
