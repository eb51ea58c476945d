//! The plots of `twin hybrid`: the threshold of contact against the actuator's amplitude error
//! (the reference paper's Fig. 14), and floor 2's displacement in time and frequency for each
//! run (its Fig. 15), the contacts ticked under the time histories.

use plotters::prelude::*;

use super::palette;
use crate::workflows::hybrid::experiment::{RunOutcome, ThresholdCurve};

const FONT: &str = "sans-serif";
const COLOURS: [RGBColor; 4] = [
    palette::BLUE,
    palette::VERMILION,
    palette::GREEN,
    palette::ORANGE,
];

fn text(e: impl std::fmt::Display) -> String {
    e.to_string()
}

fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let pad = 0.05 * (hi - lo).max(1e-12);
    (lo - pad, hi + pad)
}

type Chart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// A panel's grid and axis labels.
fn mesh(chart: &mut Chart<'_, '_>, x: &str, y: &str) -> Result<(), String> {
    chart
        .configure_mesh()
        .x_desc(x)
        .y_desc(y)
        .label_style((FONT, 11))
        .light_line_style(BLACK.mix(0.04))
        .draw()
        .map_err(text)
}

/// Fig. 14: the threshold peak force against a_err, the bisection on the test and the linear
/// assembly's independent value.
pub fn threshold_svg(curve: &ThresholdCurve) -> Result<String, String> {
    if curve.thresholds.is_empty() {
        return Err("no threshold to plot (every point failed)".into());
    }
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 560)).into_drawing_area();
        root.fill(&WHITE).map_err(text)?;
        let x = range(curve.thresholds.iter().map(|p| p.a_err));
        let y = range(
            curve
                .thresholds
                .iter()
                .flat_map(|p| [p.threshold_peak_force, p.independent]),
        );
        let mut chart = ChartBuilder::on(&root)
            .margin(16)
            .caption(
                "hybrid test: peak excitation at which the bumper first closes",
                (FONT, 18),
            )
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x.0..x.1, y.0..y.1)
            .map_err(text)?;
        chart
            .configure_mesh()
            .x_desc("actuator amplitude error a_err")
            .y_desc("threshold peak force (N)")
            .label_style((FONT, 12))
            .light_line_style(BLACK.mix(0.04))
            .draw()
            .map_err(text)?;
        let points: Vec<(f64, f64)> = curve
            .thresholds
            .iter()
            .map(|p| (p.a_err, p.threshold_peak_force))
            .collect();
        chart
            .draw_series(LineSeries::new(
                points.clone(),
                palette::BLUE.stroke_width(2),
            ))
            .map_err(text)?
            .label("bisection on the hybrid test")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], palette::BLUE));
        chart
            .draw_series(
                points
                    .iter()
                    .map(|&p| Circle::new(p, 4, palette::BLUE.filled())),
            )
            .map_err(text)?;
        chart
            .draw_series(curve.thresholds.iter().map(|p| {
                Cross::new(
                    (p.a_err, p.independent),
                    6,
                    palette::VERMILION.stroke_width(2),
                )
            }))
            .map_err(text)?
            .label("gap / peak y_r of the linear assembly")
            .legend(|(x, y)| Cross::new((x + 9, y), 5, palette::VERMILION));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK)
            .label_font((FONT, 13))
            .draw()
            .map_err(text)?;
        root.present().map_err(text)?;
    }
    Ok(svg)
}

/// Fig. 15: per run, floor 2's displacement over time (contacts ticked) and its spectrum.
pub fn runs_svg(outcomes: &[RunOutcome], dt: f64) -> Result<String, String> {
    let shown: Vec<&RunOutcome> = outcomes.iter().filter(|o| o.run.is_some()).collect();
    if shown.is_empty() {
        return Err("no completed run to plot".into());
    }
    let mut svg = String::new();
    {
        let height = 300 * shown.len() as u32;
        let root = SVGBackend::with_string(&mut svg, (1400, height)).into_drawing_area();
        root.fill(&WHITE).map_err(text)?;
        let rows = root.split_evenly((shown.len(), 2));
        for (i, o) in shown.iter().enumerate() {
            let (Some(run), Some(spectrum)) = (&o.run, &o.spectrum) else {
                continue;
            };
            let colour = COLOURS[i % COLOURS.len()];
            let title = format!(
                "a_err = {:+.3}: {} contacts",
                o.summary.a_err, o.summary.contacts
            );
            let t_end = run.time.last().copied().unwrap_or(1.0).max(dt);
            let y = range(run.yjp.iter().map(|v| 1e3 * v));
            let mut chart = ChartBuilder::on(&rows[2 * i])
                .margin(10)
                .caption(format!("{title}: floor 2 (physical side)"), (FONT, 15))
                .x_label_area_size(34)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..t_end, y.0..y.1)
                .map_err(text)?;
            mesh(&mut chart, "time (s)", "y2 (mm)")?;
            chart
                .draw_series(LineSeries::new(
                    run.time.iter().zip(&run.yjp).map(|(t, v)| (*t, 1e3 * v)),
                    colour.stroke_width(1),
                ))
                .map_err(text)?;
            let tick = y.0 + 0.04 * (y.1 - y.0);
            chart
                .draw_series(run.contact_times.iter().map(|&t| {
                    PathElement::new(vec![(t, y.0), (t, tick)], palette::RED.stroke_width(1))
                }))
                .map_err(text)?;
            let top = spectrum
                .power
                .iter()
                .copied()
                .fold(f64::MIN_POSITIVE, f64::max);
            let db: Vec<(f64, f64)> = spectrum
                .frequency
                .iter()
                .zip(&spectrum.power)
                .skip(1)
                .map(|(f, p)| (*f, 10.0 * (p.max(top * 1e-12) / top).log10()))
                .collect();
            let f_max = spectrum.frequency.last().copied().unwrap_or(1.0).min(60.0);
            let mut chart = ChartBuilder::on(&rows[2 * i + 1])
                .margin(10)
                .caption(format!("{title}: spectrum of floor 2"), (FONT, 15))
                .x_label_area_size(34)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..f_max, -80.0..5.0)
                .map_err(text)?;
            mesh(&mut chart, "frequency (Hz)", "power (dB re peak)")?;
            chart
                .draw_series(LineSeries::new(
                    db.into_iter().filter(|(f, _)| *f <= f_max),
                    colour.stroke_width(1),
                ))
                .map_err(text)?;
            if let Some(h) = &o.summary.spectrum {
                chart
                    .draw_series(h.harmonics.iter().map(|(_, p)| {
                        Circle::new((p.frequency, p.relative_db), 4, palette::RED.filled())
                    }))
                    .map_err(text)?;
            }
        }
        root.present().map_err(text)?;
    }
    Ok(svg)
}
