//! The plot of one active-learning mode: NMSE against updates per record (the paper's Figs
//! 9–10), and on the last record the corrected prediction with query marks and the latent
//! variance against the threshold (Figs 11–12).

use ::structure::channel::{Channel, Quantity};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::RGBColor;

use super::palette;
use crate::workflows::learn::{ModeResult, RecordResult, Trace};

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

type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;

fn text(e: &dyn std::fmt::Display) -> String {
    e.to_string()
}

/// What a mode's channels are called and measured in: "floor i" on the paper's rig, the
/// channel's name otherwise; per channel the unit of its values and of its latent variance.
struct Channels {
    labels: Vec<String>,
    units: Vec<(&'static str, &'static str)>,
}

impl Channels {
    fn of(result: &ModeResult) -> Channels {
        let channels = result
            .records
            .first()
            .map(|r| r.trace.channels.clone())
            .unwrap_or_default();
        let labels = result.channel_labels.clone();
        let units = (0..labels.len())
            .map(|f| match channels.get(f).and_then(|c| Channel::parse(c)) {
                Some(c) if c.quantity() == Quantity::Velocity => ("m/s", "V(f) (m/s)²"),
                Some(c) if c.quantity() == Quantity::Displacement => ("m", "V(f) m²"),
                _ => ("m/s²", "V(f) (m/s²)²"),
            })
            .collect();
        Channels { labels, units }
    }
}

/// One SVG for a mode: the title, NMSE against updates per record along the top, and per
/// channel the last record's trace above its latent variance.
pub fn plot_mode(result: &ModeResult) -> Result<String, String> {
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
        let channels = Channels::of(result);
        let (top, bottom) = body.split_vertically(380);
        let columns = top.split_evenly((1, result.records.len().max(1)));
        for (k, (area, rec)) in columns.iter().zip(&result.records).enumerate() {
            draw_updates(area, k, rec, &channels)?;
        }
        let Some(last) = result.records.last() else {
            return Err("no record".into());
        };
        let rows = bottom.split_evenly((channels.labels.len().max(1), 1));
        for (f, row) in rows.iter().enumerate() {
            let (upper, lower) = row.split_vertically(row.dim_in_pixel().1 * 3 / 5);
            draw_trace(&upper, f, last, &channels)?;
            draw_latent(&lower, f, last, &channels)?;
        }
        root.present().map_err(|e| text(&e))?;
    }
    Ok(svg)
}

/// Record `k`'s NMSE per channel against the updates (the paper's Figs 9–10).
fn draw_updates(
    area: &Area<'_>,
    k: usize,
    rec: &RecordResult,
    channels: &Channels,
) -> Result<(), String> {
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
    for (f, label) in channels.labels.iter().enumerate() {
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
    Ok(())
}

/// The streamed part's time span of the last record's trace.
fn time_span(trace: &Trace) -> (f64, f64) {
    let t0 = trace.time.first().copied().unwrap_or(0.0);
    (t0, trace.time.last().copied().unwrap_or(1.0).max(t0 + 1e-9))
}

/// Channel `f` of the last record: measured and corrected over the streamed part, the query
/// times marked.
fn draw_trace(
    area: &Area<'_>,
    f: usize,
    last: &RecordResult,
    channels: &Channels,
) -> Result<(), String> {
    let trace = &last.trace;
    let (t0, t1) = time_span(trace);
    let n = trace.corrected[f].len();
    let offset = n - trace.time.len();
    // A channel's series over the streamed part, against its time.
    let streamed = |series: &[f64]| -> Vec<(f64, f64)> {
        trace
            .time
            .iter()
            .enumerate()
            .map(|(i, &t)| (t, series[offset + i]))
            .collect()
    };
    let measured = streamed(&trace.measured[f]);
    let predicted = streamed(&trace.corrected[f]);
    let (lo, hi) = measured
        .iter()
        .chain(&predicted)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (_, v)| {
            (a.min(*v), b.max(*v))
        });
    let pad = 0.05 * (hi - lo).max(1e-9);
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!(
                "last record, {}: measured, corrected (final GP), queries (red)",
                channels.labels[f]
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
        .y_desc(channels.units[f].0)
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
    Ok(())
}

/// Channel `f`'s latent variance on the last record against the threshold at decision time
/// (the paper's Figs 11–12).
fn draw_latent(
    area: &Area<'_>,
    f: usize,
    last: &RecordResult,
    channels: &Channels,
) -> Result<(), String> {
    let trace = &last.trace;
    let (t0, t1) = time_span(trace);
    let finite_threshold = trace.threshold[f].iter().any(|t| t.is_finite());
    let (lo, hi) = log_range(
        trace.latent[f]
            .iter()
            .copied()
            .chain(trace.threshold[f].iter().copied().filter(|t| t.is_finite())),
    );
    let mut chart = ChartBuilder::on(area)
        .margin(6)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(t0..t1, (lo..hi).log_scale())
        .map_err(|e| text(&e))?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc(channels.units[f].1)
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
    Ok(())
}

/// `twin learn --out-dir DIR`'s plots: one SVG per mode, `DIR/learn-TAG.svg`; their paths.
pub fn write_plots(
    results: &[ModeResult],
    dir: &std::path::Path,
) -> Result<Vec<std::path::PathBuf>, super::ReportError> {
    std::fs::create_dir_all(dir).map_err(|e| super::ReportError::BadInput {
        path: dir.to_owned(),
        message: format!("cannot create the directory: {e}"),
    })?;
    let mut written = Vec::new();
    for r in results {
        let path = dir.join(format!("learn-{}.svg", r.mode_tag()));
        let svg = plot_mode(r).map_err(|message| super::ReportError::Draw {
            path: path.clone(),
            message,
        })?;
        crate::fsutil::write_text_atomically(&path, &svg)?;
        written.push(path);
    }
    Ok(written)
}
