//! The FRF overlay of `twin compare --frf FRF --plot` and `twin calibrate --frf --plot`: per
//! measured channel, the measured magnitude, the twin's exact one and its ±3σ band from the
//! posterior, with the twin's natural frequencies and the measured peaks marked.

use std::path::Path;

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use super::{palette, ReportError};
use crate::workflows::compare::{FrfChannelView, FrfView};

const FONT: &str = "sans-serif";
const SIZE: (u32, u32) = (1400, 300);
const PANEL_HEIGHT: u32 = 260;
const MEASURED: RGBColor = palette::BLUE;
const TWIN: RGBColor = palette::ORANGE;
const BAND: RGBColor = palette::GREEN;
const PEAK: RGBColor = palette::GREY;

fn text(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// The overlay as SVG text (nothing written: the caller writes it atomically). `path` must end
/// in `.svg`; it names the file in errors.
pub fn draw_frf_comparison(
    view: &FrfView,
    title: &str,
    path: &Path,
) -> Result<String, ReportError> {
    if path.extension().and_then(|e| e.to_str()) != Some("svg") {
        return Err(ReportError::UnsupportedFormat {
            path: path.to_owned(),
        });
    }
    let bad = |message: String| ReportError::BadInput {
        path: path.to_owned(),
        message,
    };
    if view.channels.is_empty() || view.frequency.len() < 2 {
        return Err(bad(
            "no channel or fewer than 2 frequency lines to draw".into()
        ));
    }
    draw(view, title).map_err(|message| ReportError::Draw {
        path: path.to_owned(),
        message,
    })
}

fn draw(view: &FrfView, title: &str) -> Result<String, String> {
    let f0 = view.frequency[0];
    let f1 = view.frequency[view.frequency.len() - 1];
    let mut svg = String::new();
    {
        let height = 80 + PANEL_HEIGHT * view.channels.len() as u32;
        let root =
            SVGBackend::with_string(&mut svg, (SIZE.0, height.max(SIZE.1))).into_drawing_area();
        root.fill(&WHITE).map_err(text)?;
        let root = root
            .titled(&format!("{title} — frequency response"), (FONT, 22))
            .map_err(text)?;
        let (key, panels) = root.split_vertically(30);
        let offset = view
            .gain_offset_db
            .map(|g| format!("; measured shifted by {:+.2} dB (unknown dB reference)", -g))
            .unwrap_or_default();
        key.draw(&Text::new(
            format!(
                "blue: measured   orange: twin (exact, linear structure)   green: twin ±3σ (posterior)   \
                 grey dashes: measured peaks{offset}"
            ),
            (90, 8),
            (FONT, 14),
        ))
        .map_err(text)?;
        for (i, area) in panels
            .split_evenly((view.channels.len(), 1))
            .iter()
            .enumerate()
        {
            draw_channel(area, view, &view.channels[i], (f0, f1))?;
        }
        root.present().map_err(text)?;
    }
    Ok(svg)
}

type FrequencyChart<'a, 'b> =
    ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// One channel's panel over the band `(f0, f1)`: its ±3σ band, the measured peaks, the measured
/// and twin magnitudes and the twin's natural frequencies.
fn draw_channel(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    view: &FrfView,
    c: &FrfChannelView,
    (f0, f1): (f64, f64),
) -> Result<(), String> {
    let (lo, hi) = db_range(c);
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!("{} — RMS error {:.2} dB", c.channel, c.rms_error_db),
            (FONT, 16),
        )
        .margin_left(10)
        .margin_right(20)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(f0..f1, lo..hi)
        .map_err(text)?;
    chart
        .configure_mesh()
        .x_desc("frequency (Hz)")
        .y_desc("|H| (dB re 1 SI per unit excitation)")
        .label_style((FONT, 12))
        .axis_desc_style((FONT, 13))
        .light_line_style(BLACK.mix(0.04))
        .draw()
        .map_err(text)?;
    draw_band(&mut chart, view, c, (lo, hi))?;
    for peak in &view.measured_peaks {
        let f = peak.frequency_hz;
        chart
            .draw_series(DashedLineSeries::new(
                vec![(f, lo), (f, hi)],
                4,
                4,
                PEAK.stroke_width(1),
            ))
            .map_err(text)?;
    }
    for (values, colour) in [(&c.measured_db, MEASURED), (&c.twin_db, TWIN)] {
        let line = view
            .frequency
            .iter()
            .zip(values.iter())
            .filter(|(_, v)| v.is_finite())
            .map(|(f, v)| (*f, v.clamp(lo, hi)));
        chart
            .draw_series(LineSeries::new(line, colour.stroke_width(1)))
            .map_err(text)?;
    }
    for mode in &view.twin_modes {
        let f = mode.frequency_hz.value;
        if f >= f0 && f <= f1 {
            chart
                .draw_series(std::iter::once(Text::new(
                    format!("{f:.2} Hz"),
                    (f, hi - 0.06 * (hi - lo)),
                    (FONT, 11).into_font().color(&TWIN),
                )))
                .map_err(text)?;
        }
    }
    Ok(())
}

/// The panel's dB range: the measured and twin magnitudes', at most 100 dB deep, padded 3 dB.
fn db_range(c: &FrfChannelView) -> (f64, f64) {
    let values = c
        .measured_db
        .iter()
        .chain(&c.twin_db)
        .copied()
        .filter(|v| v.is_finite());
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if lo.is_finite() {
        (lo.max(hi - 100.0) - 3.0, hi + 3.0)
    } else {
        (-1.0, 1.0)
    }
}

/// The twin's ±3σ band from the posterior, when it has one, clamped to the panel.
fn draw_band(
    chart: &mut FrequencyChart,
    view: &FrfView,
    c: &FrfChannelView,
    (lo, hi): (f64, f64),
) -> Result<(), String> {
    if let Some(sd) = &c.twin_sd_db {
        let upper = view
            .frequency
            .iter()
            .zip(c.twin_db.iter().zip(sd))
            .map(|(f, (t, s))| (*f, (t + 3.0 * s).clamp(lo, hi)));
        let lower = view
            .frequency
            .iter()
            .zip(c.twin_db.iter().zip(sd))
            .rev()
            .map(|(f, (t, s))| (*f, (t - 3.0 * s).clamp(lo, hi)));
        let polygon: Vec<(f64, f64)> = upper.chain(lower).collect();
        chart
            .draw_series(std::iter::once(Polygon::new(
                polygon,
                BAND.mix(0.3).filled(),
            )))
            .map_err(text)?;
    }
    Ok(())
}
