//! The plots of modes identified from a record: the stabilisation diagram of each method over
//! the record's spectrum, and the FRF of every channel with its coherence.

use std::path::{Path, PathBuf};

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use super::{palette, ReportError};
use crate::fsutil::write_text_atomically;
use crate::workflows::modal::identify::{ChannelFrf, FrfReport, MethodModes, RecordModes};

const STABLE: RGBColor = palette::BLUE;
const FREQUENCY_ONLY: RGBColor = palette::ORANGE;
const UNSTABLE: RGBColor = palette::GREY;
const MODE: RGBColor = palette::VERMILION;
const SPECTRUM: RGBColor = palette::DARK_GREY;
const PANEL: (u32, u32) = (960, 420);

/// `P.svg` → `P-frf.svg`, beside it.
pub fn frf_path(plot: &Path) -> PathBuf {
    let stem = plot
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "modal".into());
    plot.with_file_name(format!("{stem}-frf.svg"))
}

/// Writes the stabilisation diagram of each method (input–output first) as an SVG at `path`:
/// poles by model order and frequency (stable in frequency, damping and shape; in frequency
/// only; not stable), the chosen modes as vertical lines, the spectrum behind (log scale).
pub fn plot_stabilisation(record: &RecordModes, path: &Path) -> Result<(), ReportError> {
    let svg = draw_stabilisation(record).map_err(|message| ReportError::Draw {
        path: path.to_owned(),
        message,
    })?;
    write_text_atomically(path, &svg)?;
    Ok(())
}

fn draw_stabilisation(record: &RecordModes) -> Result<String, String> {
    let methods: Vec<&MethodModes> = record
        .input_output
        .iter()
        .chain(std::iter::once(&record.ssi))
        .collect();
    let top = record
        .input_output
        .as_ref()
        .and_then(|m| m.band)
        .map_or(0.5 / record.dt, |(_, high)| high);
    let mut svg = String::new();
    {
        let size = (PANEL.0, PANEL.1 * methods.len() as u32 + 40);
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let root = root
            .titled(
                &format!("{} — stabilisation diagrams", record.records.join(", ")),
                ("sans-serif", 18),
            )
            .map_err(|e| err(&e))?;
        for (method, area) in methods.iter().zip(root.split_evenly((methods.len(), 1))) {
            stabilisation_panel(&area, record, method, top)?;
        }
        root.present().map_err(|e| err(&e))?;
    }
    Ok(svg)
}

/// A drawing error as the message the caller reports.
fn err(e: &dyn std::fmt::Display) -> String {
    e.to_string()
}

type Chart<'a, 'b> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// One method's stabilisation diagram in `area`: the spectrum behind, the chosen modes, the
/// poles by how stable they are, and the legend.
fn stabilisation_panel(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    record: &RecordModes,
    method: &MethodModes,
    top: f64,
) -> Result<(), String> {
    let max_order = method
        .diagram
        .orders
        .iter()
        .map(|o| o.order)
        .max()
        .unwrap_or(2) as f64;
    let mut chart = ChartBuilder::on(area)
        .margin(12)
        .caption(
            format!("{}: {} modes chosen", method.method, method.modes.len()),
            ("sans-serif", 14),
        )
        .x_label_area_size(36)
        .y_label_area_size(48)
        .build_cartesian_2d(0f64..top, 0f64..max_order + 2.0)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("frequency (Hz)")
        .y_desc("model order")
        .draw()
        .map_err(|e| err(&e))?;
    draw_spectrum(&mut chart, record, top, max_order)?;
    for mode in &method.modes {
        let f = mode.identified.frequency;
        chart
            .draw_series(std::iter::once(PathElement::new(
                [(f, 0.0), (f, max_order + 2.0)],
                MODE.mix(0.7).stroke_width(1),
            )))
            .map_err(|e| err(&e))?;
    }
    draw_poles(&mut chart, &PolesByStability::of(method, top))?;
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(palette::GREY)
        .label_font(("sans-serif", 11))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| err(&e))?;
    Ok(())
}

/// The spectrum, log10 of the summed PSDs mapped onto the order axis.
fn draw_spectrum(
    chart: &mut Chart,
    record: &RecordModes,
    top: f64,
    max_order: f64,
) -> Result<(), String> {
    let points: Vec<(f64, f64)> = record
        .spectrum
        .frequencies
        .iter()
        .zip(&record.spectrum.total)
        .filter(|(f, p)| **f > 0.0 && **f <= top && **p > 0.0)
        .map(|(f, p)| (*f, p.log10()))
        .collect();
    let (low, high) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), (_, v)| {
            (l.min(*v), h.max(*v))
        });
    if high > low {
        let scale = max_order / (high - low);
        chart
            .draw_series(LineSeries::new(
                points.iter().map(|(f, v)| (*f, 1.0 + (v - low) * scale)),
                SPECTRUM.mix(0.5).stroke_width(1),
            ))
            .map_err(|e| err(&e))?
            .label("spectrum (Σ PSD, log scale)")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 16, y)], SPECTRUM));
    }
    Ok(())
}

/// A method's poles up to `top` Hz as (frequency, order), by how stable each is.
struct PolesByStability {
    /// Stable in frequency, damping and shape.
    stable: Vec<(f64, f64)>,
    /// Stable in frequency only.
    frequency_only: Vec<(f64, f64)>,
    unstable: Vec<(f64, f64)>,
}

impl PolesByStability {
    fn of(method: &MethodModes, top: f64) -> Self {
        let poles = method.diagram.orders.iter().flat_map(|o| {
            o.poles
                .iter()
                .filter(move |p| p.frequency <= top)
                .map(move |p| (o.order as f64, p))
        });
        let (mut stable, mut frequency_only, mut unstable) = (vec![], vec![], vec![]);
        for (order, p) in poles {
            if p.stable.all() {
                stable.push((p.frequency, order));
            } else if p.stable.frequency {
                frequency_only.push((p.frequency, order));
            } else {
                unstable.push((p.frequency, order));
            }
        }
        PolesByStability {
            stable,
            frequency_only,
            unstable,
        }
    }
}

/// The poles as dots (filled when stable, rings when stable in frequency only), and the
/// chosen modes' legend entry.
fn draw_poles(chart: &mut Chart, poles: &PolesByStability) -> Result<(), String> {
    chart
        .draw_series(
            poles
                .unstable
                .iter()
                .map(|&p| Circle::new(p, 2, UNSTABLE.filled())),
        )
        .map_err(|e| err(&e))?
        .label("not stable")
        .legend(|(x, y)| Circle::new((x + 8, y), 2, UNSTABLE.filled()));
    chart
        .draw_series(
            poles
                .frequency_only
                .iter()
                .map(|&p| Circle::new(p, 3, FREQUENCY_ONLY.stroke_width(1))),
        )
        .map_err(|e| err(&e))?
        .label("stable in frequency")
        .legend(|(x, y)| Circle::new((x + 8, y), 3, FREQUENCY_ONLY.stroke_width(1)));
    chart
        .draw_series(
            poles
                .stable
                .iter()
                .map(|&p| Circle::new(p, 3, STABLE.filled())),
        )
        .map_err(|e| err(&e))?
        .label("stable in frequency, damping and shape")
        .legend(|(x, y)| Circle::new((x + 8, y), 3, STABLE.filled()));
    chart
        .draw_series(std::iter::once(PathElement::new(
            [(0.0, -1.0), (0.0, -1.0)],
            MODE,
        )))
        .map_err(|e| err(&e))?
        .label("chosen mode")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 16, y)], MODE));
    Ok(())
}

/// Writes the FRF (magnitude, dB re 1 SI unit per excitation unit) and the coherence of every
/// channel as an SVG at `path`. The record must have been identified with its excitation.
pub fn plot_frf(record: &RecordModes, path: &Path) -> Result<(), ReportError> {
    let Some(frf) = &record.frf else {
        return Err(ReportError::BadInput {
            path: path.to_owned(),
            message: "the record's excitation carries no power: no FRF".into(),
        });
    };
    let svg = draw_frf(record, frf).map_err(|message| ReportError::Draw {
        path: path.to_owned(),
        message,
    })?;
    write_text_atomically(path, &svg)?;
    Ok(())
}

fn draw_frf(record: &RecordModes, frf: &FrfReport) -> Result<String, String> {
    let top = record
        .input_output
        .as_ref()
        .and_then(|m| m.band)
        .map_or(0.5 / record.dt, |(_, high)| high);
    let mut svg = String::new();
    {
        let rows = frf.channels.len().max(1) as u32;
        let size = (PANEL.0, 300 * rows + 40);
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let root = root
            .titled(
                &format!(
                    "{} — FRF (H1, {} segments of {}) and coherence",
                    record.records.join(", "),
                    frf.segments,
                    frf.segment_length
                ),
                ("sans-serif", 18),
            )
            .map_err(|e| err(&e))?;
        for (channel, area) in frf
            .channels
            .iter()
            .zip(root.split_evenly((frf.channels.len(), 1)))
        {
            let (upper, lower) = area.split_vertically(200);
            draw_magnitude(&upper, record, &frf.frequencies, channel, top)?;
            draw_coherence(&lower, &frf.frequencies, channel, top)?;
        }
        root.present().map_err(|e| err(&e))?;
    }
    Ok(svg)
}

/// A channel's |H| in dB up to `top` Hz, with the chosen modes as vertical lines.
fn draw_magnitude(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    record: &RecordModes,
    frequencies: &[f64],
    channel: &ChannelFrf,
    top: f64,
) -> Result<(), String> {
    let magnitude: Vec<(f64, f64)> = frequencies
        .iter()
        .zip(&channel.response)
        .filter(|(f, h)| **f > 0.0 && **f <= top && h.norm() > 0.0)
        .map(|(f, h)| (*f, 20.0 * h.norm().log10()))
        .collect();
    let (low, high) = magnitude
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), (_, v)| {
            (l.min(*v), h.max(*v))
        });
    let (low, high) = if high > low {
        (low - 3.0, high + 3.0)
    } else {
        (-1.0, 1.0)
    };
    let mut chart = ChartBuilder::on(area)
        .margin(8)
        .caption(
            format!("{} — |H| in dB re 1 {}", channel.channel, channel.unit),
            ("sans-serif", 13),
        )
        .x_label_area_size(20)
        .y_label_area_size(48)
        .build_cartesian_2d(0f64..top, low..high)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .y_desc("dB")
        .draw()
        .map_err(|e| err(&e))?;
    chart
        .draw_series(LineSeries::new(magnitude, STABLE.stroke_width(1)))
        .map_err(|e| err(&e))?;
    let modes = record
        .input_output
        .as_ref()
        .map_or(&record.ssi.modes, |m| &m.modes);
    for mode in modes {
        let f = mode.identified.frequency;
        chart
            .draw_series(std::iter::once(PathElement::new(
                [(f, low), (f, high)],
                MODE.mix(0.6).stroke_width(1),
            )))
            .map_err(|e| err(&e))?;
    }
    Ok(())
}

/// A channel's coherence up to `top` Hz.
fn draw_coherence(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    frequencies: &[f64],
    channel: &ChannelFrf,
    top: f64,
) -> Result<(), String> {
    let mut coherence = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(48)
        .build_cartesian_2d(0f64..top, 0f64..1.05f64)
        .map_err(|e| err(&e))?;
    coherence
        .configure_mesh()
        .x_desc("frequency (Hz)")
        .y_desc("coherence")
        .y_labels(3)
        .draw()
        .map_err(|e| err(&e))?;
    coherence
        .draw_series(LineSeries::new(
            frequencies
                .iter()
                .zip(&channel.coherence)
                .filter(|(f, _)| **f > 0.0 && **f <= top)
                .map(|(f, c)| (*f, *c)),
            palette::GREEN.stroke_width(1),
        ))
        .map_err(|e| err(&e))?;
    Ok(())
}
