//! Mode shapes along the height: one panel per mode, the shape's component at each floor (the
//! ground at 0) with its ±2 sd, and the modes identified from a record at the floors it measures
//! beside the twin's; and the MAC matrix of the twin's modes against a record's.

use std::path::Path;

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use super::{palette, ReportError};
use crate::fsutil::write_text_atomically;
use crate::workflows::modal::{ModeComparison, TwinMode, TwinModes};

const TWIN: RGBColor = palette::BLUE;
const OBSERVED: RGBColor = palette::VERMILION;
const PANEL: (u32, u32) = (260, 520);

/// Shapes of an observed mode at `floors` (1-based), real parts, for the panels.
pub struct ObservedShapes<'a> {
    pub floors: &'a [usize],
    /// Per observed mode: (frequency Hz, shape at the floors).
    pub modes: Vec<(f64, Vec<f64>)>,
    pub comparison: Option<&'a ModeComparison>,
}

/// The plot of an ambient record's diagnosis (`twin diagnose` on responses alone): the twin's
/// shapes along the height with the record's identified ones beside them, each panel titled
/// with both frequencies.
pub fn draw_ambient_diagnosis(
    d: &crate::workflows::diagnose::AmbientDiagnosis,
) -> Result<String, String> {
    let observed: Vec<(f64, Vec<f64>)> = d
        .identified
        .iter()
        .map(|m| (m.frequency, m.shape.clone()))
        .collect();
    let shapes = ObservedShapes {
        floors: &d.modes.floors,
        modes: observed,
        comparison: Some(&d.modes.comparison),
    };
    draw_mode_shapes(&d.twin_modes, Some(&shapes))
}

/// Writes the mode-shape view of `twin` (and of `observed`, when given) as an SVG at `path`.
pub fn plot_mode_shapes(
    twin: &TwinModes,
    observed: Option<&ObservedShapes>,
    path: &Path,
) -> Result<(), ReportError> {
    let svg = draw_mode_shapes(twin, observed).map_err(|message| ReportError::Draw {
        path: path.to_owned(),
        message,
    })?;
    write_text_atomically(path, &svg)?;
    Ok(())
}

/// The mode-shape view as SVG text.
pub fn draw_mode_shapes(
    twin: &TwinModes,
    observed: Option<&ObservedShapes>,
) -> Result<String, String> {
    let panels = twin.modes.len().max(1);
    let size = (PANEL.0 * panels as u32 + 40, PANEL.1 + 60);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let root = root
            .titled(
                &format!("{} — mode shapes along the height (±2 sd)", twin.twin),
                ("sans-serif", 18),
            )
            .map_err(|e| err(&e))?;
        let areas = root.split_evenly((1, panels));
        for (mode, area) in twin.modes.iter().zip(areas.iter()) {
            mode_panel(area, twin.storeys, mode, observed)?;
        }
        root.present().map_err(|e| err(&e))?;
    }
    Ok(svg)
}

/// A drawing error as the message the caller reports.
fn err(e: &dyn std::fmt::Display) -> String {
    e.to_string()
}

type ShapeChart<'a, 'b> =
    ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// One twin mode's panel: its shape along the `storeys` floors with ±2 sd, the observed mode
/// paired with it (when given) and the legend.
fn mode_panel(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    storeys: usize,
    mode: &TwinMode,
    observed: Option<&ObservedShapes>,
) -> Result<(), String> {
    let sd = |v: Option<f64>| v.map(|s| format!(" ± {:.2e}", s)).unwrap_or_default();
    let caption = format!(
        "mode {}: {:.3}{} Hz, ζ {:.3}{} %",
        mode.number,
        mode.frequency,
        sd(mode.frequency_sd),
        100.0 * mode.damping,
        mode.damping_sd
            .map(|s| format!(" ± {:.2e}", 100.0 * s))
            .unwrap_or_default()
    );
    let mut chart = ChartBuilder::on(area)
        .margin(10)
        .caption(caption, ("sans-serif", 13))
        .x_label_area_size(30)
        .y_label_area_size(30)
        .build_cartesian_2d(-1.3f64..1.3f64, 0f64..storeys as f64 + 0.3)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .y_desc("floor")
        .x_labels(5)
        .y_labels(storeys + 1)
        .y_label_formatter(&|y| format!("{y:.0}"))
        .draw()
        .map_err(|e| err(&e))?;
    draw_twin_shape(&mut chart, mode)?;
    if let Some(obs) = observed {
        draw_observed_partner(&mut chart, mode, obs)?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(palette::GREY)
        .label_font(("sans-serif", 11))
        .position(SeriesLabelPosition::LowerLeft)
        .draw()
        .map_err(|e| err(&e))?;
    Ok(())
}

/// The twin's shape from the ground up, its ±2 sd bars and a dot at each floor.
fn draw_twin_shape(chart: &mut ShapeChart, mode: &TwinMode) -> Result<(), String> {
    let points: Vec<(f64, f64)> = std::iter::once((0.0, 0.0))
        .chain(
            mode.shape
                .iter()
                .enumerate()
                .map(|(i, &x)| (x, (i + 1) as f64)),
        )
        .collect();
    chart
        .draw_series(LineSeries::new(points.clone(), TWIN.stroke_width(2)))
        .map_err(|e| err(&e))?
        .label("twin")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 16, y)], TWIN.stroke_width(2)));
    if let Some(sds) = &mode.shape_sd {
        chart
            .draw_series(mode.shape.iter().zip(sds).enumerate().map(|(i, (&x, &s))| {
                let y = (i + 1) as f64;
                PathElement::new([(x - 2.0 * s, y), (x + 2.0 * s, y)], TWIN.stroke_width(3))
            }))
            .map_err(|e| err(&e))?;
    }
    chart
        .draw_series(
            points
                .iter()
                .skip(1)
                .map(|&p| Circle::new(p, 3, TWIN.filled())),
        )
        .map_err(|e| err(&e))?;
    Ok(())
}

/// The observed mode paired with this one, at the floors the record measures, scaled to the
/// twin's shape there (least squares) so that the two lie together.
fn draw_observed_partner(
    chart: &mut ShapeChart,
    mode: &TwinMode,
    obs: &ObservedShapes,
) -> Result<(), String> {
    let partner = obs.comparison.and_then(|c| {
        c.pairs
            .iter()
            .find(|p| p.twin_mode == mode.number)
            .map(|p| (p.observed_mode - 1, p.mac))
    });
    let Some((j, mac)) = partner else {
        return Ok(());
    };
    let Some((freq, shape)) = obs.modes.get(j) else {
        return Ok(());
    };
    let twin_at: Vec<f64> = obs
        .floors
        .iter()
        .map(|&f| mode.shape.get(f.wrapping_sub(1)).copied().unwrap_or(0.0))
        .collect();
    let dot: f64 = twin_at.iter().zip(shape).map(|(a, b)| a * b).sum();
    let norm: f64 = shape.iter().map(|b| b * b).sum();
    let scale = if norm > 0.0 { dot / norm } else { 1.0 };
    chart
        .draw_series(
            obs.floors
                .iter()
                .zip(shape)
                .map(|(&f, &x)| Cross::new((scale * x, f as f64), 5, OBSERVED.stroke_width(2))),
        )
        .map_err(|e| err(&e))?
        .label(format!("record {freq:.3} Hz, MAC {mac:.3}"))
        .legend(|(x, y)| Cross::new((x + 8, y), 4, OBSERVED.stroke_width(2)));
    Ok(())
}

/// Writes the MAC matrix of a comparison (twin modes down, record modes across) as an SVG.
pub fn plot_mac_matrix(comparison: &ModeComparison, path: &Path) -> Result<(), ReportError> {
    let rows = comparison.mac_matrix.len();
    let cols = comparison.mac_matrix.first().map_or(0, Vec::len);
    if rows == 0 || cols == 0 {
        return Err(ReportError::BadInput {
            path: path.to_owned(),
            message: "the MAC matrix is empty (no twin or no identified mode)".into(),
        });
    }
    let mut svg = String::new();
    {
        let cell = 70u32;
        let size = (cell * cols as u32 + 160, cell * rows as u32 + 140);
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        let err = |e: &dyn std::fmt::Display| ReportError::Draw {
            path: path.to_owned(),
            message: e.to_string(),
        };
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .margin(20)
            .caption(
                "MAC: twin modes (down) against the record's (across)",
                ("sans-serif", 16),
            )
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(-0.5f64..cols as f64 - 0.5, -0.5f64..rows as f64 - 0.5)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("record mode")
            .y_desc("twin mode")
            .x_labels(cols)
            .y_labels(rows)
            .x_label_formatter(&|x| format!("{}", x.round() as i64 + 1))
            .y_label_formatter(&|y| format!("{}", rows as i64 - y.round() as i64))
            .draw()
            .map_err(|e| err(&e))?;
        for (i, row) in comparison.mac_matrix.iter().enumerate() {
            for (j, &v) in row.iter().enumerate() {
                let (x0, y0) = (j as f64 - 0.5, (rows - 1 - i) as f64 - 0.5);
                let shade = (255.0 * (1.0 - v.clamp(0.0, 1.0))) as u8;
                chart
                    .draw_series(std::iter::once(Rectangle::new(
                        [(x0, y0), (x0 + 1.0, y0 + 1.0)],
                        RGBColor(shade, shade, 255).filled(),
                    )))
                    .map_err(|e| err(&e))?;
                let colour = if v > 0.6 { WHITE } else { BLACK };
                chart
                    .draw_series(std::iter::once(Text::new(
                        format!("{v:.2}"),
                        (x0 + 0.3, y0 + 0.6),
                        ("sans-serif", 14).into_font().color(&colour),
                    )))
                    .map_err(|e| err(&e))?;
            }
        }
        root.present().map_err(|e| err(&e))?;
    }
    write_text_atomically(path, &svg)?;
    Ok(())
}

/// Frequencies against time in `twin watch --track-modes`: one panel per twin mode, its band
/// (the twin's frequency ± the band's half-width) shaded, the tracked frequency at each
/// identification (red where it was outside).
pub fn plot_tracked_frequencies(
    tracked: &[crate::workflows::watch::modes::Tracked],
    path: &Path,
) -> Result<(), ReportError> {
    let modes = tracked.first().map_or(0, |t| t.modes.len());
    if modes == 0 {
        return Err(ReportError::BadInput {
            path: path.to_owned(),
            message: "no identification to draw (the stream was shorter than one window?)".into(),
        });
    }
    let (t0, t1) = (
        tracked.first().map_or(0.0, |t| t.time),
        tracked.last().map_or(1.0, |t| t.time),
    );
    let (t0, t1) = if t1 > t0 {
        (t0, t1)
    } else {
        (t0 - 1.0, t0 + 1.0)
    };
    let mut svg = String::new();
    {
        let size = (1200u32, 60 + 200 * modes as u32);
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        let err = |e: &dyn std::fmt::Display| ReportError::Draw {
            path: path.to_owned(),
            message: e.to_string(),
        };
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let root = root
            .titled(
                "tracked natural frequencies against the twin's band",
                ("sans-serif", 18),
            )
            .map_err(|e| err(&e))?;
        for (i, area) in root.split_evenly((modes, 1)).iter().enumerate() {
            let twin_f = tracked[0].modes[i].twin_frequency;
            let band = tracked
                .iter()
                .map(|t| t.modes[i].band)
                .fold(0.0f64, f64::max);
            let points: Vec<(f64, f64, bool)> = tracked
                .iter()
                .filter_map(|t| {
                    t.modes[i]
                        .frequency
                        .map(|f| (t.time, f, t.modes[i].outside))
                })
                .collect();
            let (lo, hi) = points
                .iter()
                .fold((twin_f - 2.0 * band, twin_f + 2.0 * band), |(l, h), p| {
                    (l.min(p.1), h.max(p.1))
                });
            let pad = 0.05 * (hi - lo).max(1e-9);
            let mut chart = ChartBuilder::on(area)
                .margin(8)
                .caption(
                    format!("mode {}: twin {twin_f:.4} Hz ± {band:.4} Hz", i + 1),
                    ("sans-serif", 13),
                )
                .x_label_area_size(28)
                .y_label_area_size(60)
                .build_cartesian_2d(t0..t1, (lo - pad)..(hi + pad))
                .map_err(|e| err(&e))?;
            chart
                .configure_mesh()
                .x_desc("stream time (s)")
                .y_desc("Hz")
                .draw()
                .map_err(|e| err(&e))?;
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(t0, twin_f - band), (t1, twin_f + band)],
                    TWIN.mix(0.15).filled(),
                )))
                .map_err(|e| err(&e))?;
            chart
                .draw_series(LineSeries::new(
                    [(t0, twin_f), (t1, twin_f)],
                    TWIN.stroke_width(1),
                ))
                .map_err(|e| err(&e))?;
            chart
                .draw_series(points.iter().map(|&(t, f, outside)| {
                    let colour = if outside { palette::RED } else { OBSERVED };
                    Circle::new((t, f), 3, colour.filled())
                }))
                .map_err(|e| err(&e))?;
        }
        root.present().map_err(|e| err(&e))?;
    }
    write_text_atomically(path, &svg)?;
    Ok(())
}
