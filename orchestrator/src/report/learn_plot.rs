//! The plot of one active-learning mode: NMSE against updates per record (the paper's Figs
//! 9–10), and on the last record the corrected prediction with query marks and the latent
//! variance against the threshold (Figs 11–12).

use plotters::style::RGBColor;

use super::palette;
use crate::workflows::learn::ModeResult;

const MEASURED: RGBColor = palette::BLUE;
const PREDICTED: RGBColor = palette::ORANGE;
const QUERY: RGBColor = palette::RED;
const FLOORS: [RGBColor; 3] = palette::FLOORS;

fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return (1e-3, 1.0);
    }
    let (lo, hi) = if hi <= lo * 1.01 {
        (lo / 2.0, hi * 2.0)
    } else {
        (lo, hi)
    };
    (lo / 1.5, hi * 1.5)
}

/// One SVG for a mode.
pub fn plot_mode(result: &ModeResult) -> Result<String, String> {
    use plotters::prelude::*;
    let text = |e: &dyn std::fmt::Display| e.to_string();
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1400, 1500)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| text(&e))?;
        let (title, body) = root.split_vertically(40);
        title
            .draw(&Text::new(
                format!(
                    "active learning, {}: {} queries",
                    result.mode, result.total_queries
                ),
                (20, 10),
                ("sans-serif", 22).into_font(),
            ))
            .map_err(|e| text(&e))?;
        // The channels: "floor i" on the paper's rig, the channel's name otherwise.
        let channels = result
            .records
            .first()
            .map(|r| r.trace.channels.clone())
            .unwrap_or_default();
        let rig = channels.is_empty() || ::structure::building::is_paper_channels(&channels);
        let labels: Vec<String> = if rig {
            (1..=3).map(|f| format!("floor {f}")).collect()
        } else {
            channels.clone()
        };
        let unit = |f: usize| match channels
            .get(f)
            .and_then(|c| ::structure::channel::Channel::parse(c))
        {
            Some(c) if c.quantity() == ::structure::channel::Quantity::Velocity => {
                ("m/s", "V(f) (m/s)²")
            }
            Some(c) if c.quantity() == ::structure::channel::Quantity::Displacement => {
                ("m", "V(f) m²")
            }
            _ => ("m/s²", "V(f) (m/s²)²"),
        };
        let (top, bottom) = body.split_vertically(380);
        let columns = top.split_evenly((1, result.records.len().max(1)));
        for (k, (area, rec)) in columns.iter().zip(&result.records).enumerate() {
            let updates = rec
                .nmse_after_updates
                .last()
                .map(|p| p.update)
                .unwrap_or(0)
                .max(1) as f64;
            let (lo, hi) = log_range(
                rec.nmse_after_updates
                    .iter()
                    .flat_map(|p| p.nmse.iter().copied()),
            );
            let mut chart = ChartBuilder::on(area)
                .caption(
                    format!(
                        "record {}: NMSE % vs updates ({} queries)",
                        k + 1,
                        rec.queries
                    ),
                    ("sans-serif", 16),
                )
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(60)
                .build_cartesian_2d(0f64..updates, (lo..hi).log_scale())
                .map_err(|e| text(&e))?;
            chart
                .configure_mesh()
                .x_desc("update")
                .y_desc("NMSE %")
                .draw()
                .map_err(|e| text(&e))?;
            for (f, label) in labels.iter().enumerate() {
                let colour = FLOORS[f % FLOORS.len()];
                chart
                    .draw_series(LineSeries::new(
                        rec.nmse_after_updates
                            .iter()
                            .map(|p| (p.update as f64, p.nmse[f]))
                            .filter(|(_, v)| *v > 0.0),
                        colour.stroke_width(2),
                    ))
                    .map_err(|e| text(&e))?
                    .label(label)
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                    });
            }
            chart
                .configure_series_labels()
                .border_style(BLACK)
                .background_style(WHITE.mix(0.8))
                .draw()
                .map_err(|e| text(&e))?;
        }
        let Some(last) = result.records.last() else {
            return Err("no record".into());
        };
        let rows = bottom.split_evenly((labels.len().max(1), 1));
        let trace = &last.trace;
        let (t0, t1) = (
            trace.time.first().copied().unwrap_or(0.0),
            trace
                .time
                .last()
                .copied()
                .unwrap_or(1.0)
                .max(trace.time.first().copied().unwrap_or(0.0) + 1e-9),
        );
        for (f, row) in rows.iter().enumerate() {
            let (upper, lower) = row.split_vertically(row.dim_in_pixel().1 * 3 / 5);
            // Measured and corrected acceleration over the streamed part, query marks.
            let n = last.trace.corrected[f].len();
            let offset = n - trace.time.len();
            let measured: Vec<(f64, f64)> = trace
                .time
                .iter()
                .enumerate()
                .map(|(i, &t)| (t, trace.measured[f][offset + i]))
                .collect();
            let predicted: Vec<(f64, f64)> = trace
                .time
                .iter()
                .enumerate()
                .map(|(i, &t)| (t, trace.corrected[f][offset + i]))
                .collect();
            let (lo, hi) = measured
                .iter()
                .chain(&predicted)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (_, v)| {
                    (a.min(*v), b.max(*v))
                });
            let pad = 0.05 * (hi - lo).max(1e-9);
            let mut chart = ChartBuilder::on(&upper)
                .caption(
                    format!(
                        "last record, {}: measured, corrected (final GP), queries (red)",
                        labels[f]
                    ),
                    ("sans-serif", 15),
                )
                .margin(6)
                .x_label_area_size(20)
                .y_label_area_size(60)
                .build_cartesian_2d(t0..t1, (lo - pad)..(hi + pad))
                .map_err(|e| text(&e))?;
            chart
                .configure_mesh()
                .y_desc(unit(f).0)
                .draw()
                .map_err(|e| text(&e))?;
            for &q in &last.query_times {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(q, lo - pad), (q, hi + pad)],
                        QUERY.mix(0.25),
                    )))
                    .map_err(|e| text(&e))?;
            }
            chart
                .draw_series(LineSeries::new(measured, MEASURED.stroke_width(1)))
                .map_err(|e| text(&e))?;
            chart
                .draw_series(LineSeries::new(predicted, PREDICTED.stroke_width(1)))
                .map_err(|e| text(&e))?;
            // Latent variance against the threshold at decision time.
            let finite_threshold = trace.threshold[f].iter().any(|t| t.is_finite());
            let (lo, hi) = log_range(
                trace.latent[f]
                    .iter()
                    .copied()
                    .chain(trace.threshold[f].iter().copied().filter(|t| t.is_finite())),
            );
            let mut chart = ChartBuilder::on(&lower)
                .margin(6)
                .x_label_area_size(30)
                .y_label_area_size(60)
                .build_cartesian_2d(t0..t1, (lo..hi).log_scale())
                .map_err(|e| text(&e))?;
            chart
                .configure_mesh()
                .x_desc("time (s)")
                .y_desc(unit(f).1)
                .y_label_formatter(&|v| format!("{v:.0e}"))
                .draw()
                .map_err(|e| text(&e))?;
            chart
                .draw_series(LineSeries::new(
                    trace
                        .time
                        .iter()
                        .copied()
                        .zip(trace.latent[f].iter().copied())
                        .filter(|(_, v)| *v > 0.0),
                    BLACK.stroke_width(1),
                ))
                .map_err(|e| text(&e))?;
            if finite_threshold {
                chart
                    .draw_series(LineSeries::new(
                        trace
                            .time
                            .iter()
                            .copied()
                            .zip(trace.threshold[f].iter().copied())
                            .filter(|(_, v)| v.is_finite() && *v > 0.0),
                        QUERY.stroke_width(2),
                    ))
                    .map_err(|e| text(&e))?;
            }
        }
        root.present().map_err(|e| text(&e))?;
    }
    Ok(svg)
}
