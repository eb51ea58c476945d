//! SVG plots of a [`Comparison`]: the time view (the paper's Figure 4) and the frequency view
//! (its Figure 3), which draws the H1 frequency-response estimates of `evaluation::frf`
//! ([`ComparisonResponses`]), and the corrector's latent variance against the thresholds
//! `workflows::compare::compare_plot` sets. Nothing here computes: it checks and draws.

use std::fmt::Display;
use std::path::{Path, PathBuf};

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::{palette, ReportError};
use crate::evaluation::compare::Comparison;
use crate::evaluation::frf::{ComparisonResponses, FrequencyResponse};
use crate::fsutil::write_text_atomically;
use crate::workflows::compare::ComparePlot;
use ::structure::channel::{Channel, Quantity};

pub use crate::evaluation::frf::FRF_SEGMENT;

/// The frequency view reaches at most this far (dB) below its highest point, lower values drawn
/// on its bottom edge: one estimate diving toward a zero would otherwise flatten all the others.
const FRF_DEPTH_DB: f64 = 80.0;

const TIME_VIEW_SIZE: (u32, u32) = (1400, 900);
const FRF_VIEW_SIZE: (u32, u32) = (1400, 520);
/// Views with more than three channels grow by this much per panel past the third.
const TIME_PANEL_HEIGHT: u32 = 220;
const FRF_PANEL_HEIGHT: u32 = 150;

/// A view's size for `panels` channels: the three-panel size, taller past three panels.
fn view_size((width, height): (u32, u32), panels: usize, per_panel: u32) -> (u32, u32) {
    (width, height + per_panel * panels.saturating_sub(3) as u32)
}

/// The axis label of a channel's quantity in SI.
fn quantity_label(channel: &Channel) -> &'static str {
    match channel.quantity() {
        Quantity::Acceleration => "acceleration (m/s²)",
        Quantity::Velocity => "velocity (m/s)",
        Quantity::Displacement => "displacement (m)",
        Quantity::Force => "force (N)",
        Quantity::Time => "time (s)",
    }
}

/// The SI unit of a channel's quantity, as the frequency view's axis writes it.
fn unit_label(channel: &Channel) -> &'static str {
    match channel.quantity() {
        Quantity::Acceleration => "m/s²",
        Quantity::Velocity => "m/s",
        Quantity::Displacement => "m",
        Quantity::Force => "N",
        Quantity::Time => "s",
    }
}
const FONT: &str = "sans-serif";

// Okabe–Ito colours: measured, predicted and band stay apart for colour-blind readers too.
const MEASURED: RGBColor = palette::BLUE;
const PREDICTED: RGBColor = palette::ORANGE;
const BAND: RGBColor = palette::GREEN;
const RESIDUAL: RGBColor = palette::DARK_GREY;
const FAILING: RGBColor = palette::RED;
const TRANSIENT: RGBColor = palette::GREY;
const BAND_OPACITY: f64 = 0.25;
/// A failing window on a floor that left the band in it …
const FAILING_OPACITY: f64 = 0.25;
/// … and the same window, fainter, on the floors that stayed inside: it lines the panels up.
const FAILING_ELSEWHERE_OPACITY: f64 = 0.07;
const TRANSIENT_OPACITY: f64 = 0.18;

/// Writes the comparison `c` as an SVG at `path` (nothing else is accepted): one panel per
/// measured channel, captioned by its name, stacked on a shared time axis, each with the
/// measured and predicted value in the channel's quantity, the prediction ± 3σ band, the
/// residual (measured − predicted) on the same axis, the transient (left out of every error
/// measure) greyed and the failing windows shaded red — strongly on the channels that left the
/// band in the window, faintly on the others. The caption gives the channel's NMSE after the
/// transient.
///
/// With `responses` (`evaluation::frf::comparison_responses`), a second SVG is written beside
/// the first, `<stem>-frf.svg`: per channel, the H1 estimates of the response from the
/// `excitation` (force or ground acceleration) to the measured and to the predicted value, in
/// dB up to Nyquist, over the samples after the transient.
///
/// Each file is written to a temporary file in its directory and renamed into place, and
/// everything is drawn before anything is written: an error leaves no partial file.
pub fn plot_comparison(
    c: &Comparison,
    excitation: &Channel,
    responses: Option<&ComparisonResponses>,
    title: &str,
    path: &Path,
) -> Result<(), ReportError> {
    let is_svg = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("svg"));
    if !is_svg {
        return Err(ReportError::UnsupportedFormat {
            path: path.to_owned(),
        });
    }
    let bad_input = |message: String| ReportError::BadInput {
        path: path.to_owned(),
        message,
    };
    check_lengths(c, responses).map_err(bad_input)?;

    let time_view = draw_time_view(c, title).map_err(|message| ReportError::Draw {
        path: path.to_owned(),
        message,
    })?;
    let mut files = vec![(path.to_owned(), time_view)];
    if let Some(responses) = responses {
        let frf_path = frf_path(path);
        let svg = draw_frequency_view(c, responses, excitation, title).map_err(|message| {
            ReportError::Draw {
                path: frf_path.clone(),
                message,
            }
        })?;
        files.push((frf_path, svg));
    }
    for (path, svg) in &files {
        write_text_atomically(path, svg)?;
    }
    Ok(())
}

/// `twin compare --plot PATH [--frf]`: measured, predicted, ±3σ band, residual and failing
/// windows per measured channel (and the frequency-response view); with a corrector, the
/// latent-variance view of the channels it corrects beside it (`PATH-latent.svg`) against their
/// thresholds — all as `view` (`workflows::compare::compare_plot`) holds them.
pub fn plot_compared(
    comparison: &Comparison,
    excitation: &Channel,
    view: &ComparePlot,
    path: &std::path::Path,
) -> Result<(), ReportError> {
    plot_comparison(
        comparison,
        excitation,
        view.responses.as_ref(),
        &view.title,
        path,
    )?;
    let latent: Vec<(usize, &[f64], f64)> = view
        .latent
        .iter()
        .map(|l| (l.channel, l.values.as_slice(), l.threshold))
        .collect();
    if !latent.is_empty() {
        plot_latent_variance(comparison, &latent, &view.title, path)?;
    }
    Ok(())
}

/// `twin calibrate --plot PATH`: the calibrated twin's `comparison` with the calibration
/// record `data` (as [`plot_comparison`], titled by the record).
pub fn plot_calibrated(
    comparison: &Comparison,
    data: &crate::twin::data::Measurement,
    path: &Path,
) -> Result<(), ReportError> {
    let title = format!("calibrated on {}", data.path.display());
    plot_comparison(comparison, &data.excitation.channel, None, &title, path)
}

/// The corrector's latent variance `V(f)` of each channel it corrects (`latent`: the channel's
/// position in `c`, its variances, its threshold) on a log axis, with the threshold above which
/// active learning would query a point (the reference paper's Figures 7–8, lower panels),
/// written to `<dir>/<stem>-latent.svg` beside `path`. Samples above the threshold after the
/// transient are marked.
pub fn plot_latent_variance(
    c: &Comparison,
    latent: &[(usize, &[f64], f64)],
    title: &str,
    path: &Path,
) -> Result<PathBuf, ReportError> {
    let out = sibling(path, "latent");
    let bad_input = |message: String| ReportError::BadInput {
        path: out.clone(),
        message,
    };
    let n = c.time.len();
    if n < 2 {
        return Err(bad_input(format!("{n} samples; a plot needs at least 2")));
    }
    if latent.is_empty() {
        return Err(bad_input("no channel has a latent variance".into()));
    }
    for (channel, values, threshold) in latent {
        let name = c
            .channels
            .get(*channel)
            .map(Channel::name)
            .ok_or_else(|| bad_input(format!("channel {channel} is not compared")))?;
        if values.len() != n {
            return Err(bad_input(format!(
                "{name}: {} latent variances for {n} samples",
                values.len()
            )));
        }
        if !(*threshold > 0.0 && threshold.is_finite()) {
            return Err(bad_input(format!(
                "{name}: threshold {threshold}: must be positive"
            )));
        }
    }
    let svg = draw_latent_view(c, latent, title).map_err(|message| ReportError::Draw {
        path: out.clone(),
        message,
    })?;
    write_text_atomically(&out, &svg)?;
    Ok(out)
}

fn draw_latent_view(
    c: &Comparison,
    latent: &[(usize, &[f64], f64)],
    title: &str,
) -> Result<String, String> {
    let mut svg = String::new();
    {
        let size = view_size(FRF_VIEW_SIZE, latent.len(), FRF_PANEL_HEIGHT);
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(text)?;
        let root = root
            .titled(&format!("{title}: latent variance V(f)"), (FONT, 22))
            .map_err(text)?;
        let (key, panels) = root.split_vertically(30);
        draw_key(
            &key,
            &[
                KeyItem::Line(MEASURED, "latent variance V(f)"),
                KeyItem::Line(FAILING, "threshold"),
                KeyItem::Area(PREDICTED, 0.5, "above the threshold"),
            ],
            PANEL_LEFT as i32 + 10,
        )?;
        let n = c.time.len();
        let (t0, t1) = (c.time[0], c.time[n - 1]);
        for (&(channel, v, threshold), area) in latent
            .iter()
            .zip(panels.split_evenly((1, latent.len())).iter())
        {
            let positive = v.iter().copied().filter(|x| *x > 0.0 && x.is_finite());
            let (lo, hi) = positive
                .chain(std::iter::once(threshold))
                .fold((f64::INFINITY, 0.0f64), |(a, b), x| (a.min(x), b.max(x)));
            let (lo, hi) = (lo / 2.0, hi * 2.0);
            let above = (c.first..n).filter(|&k| v[k] > threshold).count();
            let unit = unit_label(&c.channels[channel]);
            let mut chart = ChartBuilder::on(area)
                .caption(
                    format!(
                        "{}: {above} of {} samples above {threshold:.2e}",
                        c.channels[channel].name(),
                        n - c.first,
                    ),
                    (FONT, 15),
                )
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(PANEL_LEFT)
                .build_cartesian_2d(t0..t1, (lo..hi).log_scale())
                .map_err(text)?;
            chart
                .configure_mesh()
                .x_desc("time (s)")
                .y_desc(format!("V(f) (({unit})²)"))
                .y_label_formatter(&|y| format!("{y:.0e}"))
                .x_labels(6)
                .y_labels(5)
                .label_style((FONT, 12))
                .light_line_style(BLACK.mix(0.04))
                .bold_line_style(BLACK.mix(0.10))
                .draw()
                .map_err(text)?;
            chart
                .draw_series((c.first..n).filter(|&k| v[k] > threshold).map(|k| {
                    Rectangle::new(
                        [(c.time[k], lo), (c.time[k] + sampling_interval(c), hi)],
                        PREDICTED.mix(0.5).filled(),
                    )
                }))
                .map_err(text)?;
            chart
                .draw_series(LineSeries::new(
                    (0..n)
                        .filter(|&k| v[k] > 0.0 && v[k].is_finite())
                        .map(|k| (c.time[k], v[k])),
                    MEASURED.stroke_width(1),
                ))
                .map_err(text)?;
            chart
                .draw_series(LineSeries::new(
                    [(t0, threshold), (t1, threshold)],
                    FAILING.stroke_width(2),
                ))
                .map_err(text)?;
        }
        root.present().map_err(text)?;
    }
    Ok(svg)
}

/// `<dir>/<stem>-<suffix>.svg` beside `<dir>/<stem>.svg`.
fn sibling(path: &Path, suffix: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!("{stem}-{suffix}.svg"))
}

/// `<dir>/<stem>-frf.svg` beside `<dir>/<stem>.svg`.
fn frf_path(path: &Path) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!("{stem}-frf.svg"))
}

fn check_lengths(c: &Comparison, responses: Option<&ComparisonResponses>) -> Result<(), String> {
    let n = c.time.len();
    if n < 2 {
        return Err(format!(
            "the record has {n} samples; a plot needs at least 2"
        ));
    }
    if c.channels.is_empty() {
        return Err("no channel to plot".into());
    }
    for (i, channel) in c.channels.iter().enumerate() {
        let (m, p) = (c.measured[i].len(), c.predicted[i].len());
        if m != n || p != n {
            return Err(format!(
                "{}: {m} measured and {p} predicted samples for {n} time samples",
                channel.name()
            ));
        }
    }
    if c.first > n {
        return Err(format!("the transient ends at sample {} of {n}", c.first));
    }
    if let Some(r) = responses {
        if r.channels.len() != c.channels.len() {
            return Err(format!(
                "{} frequency responses for {} channels",
                r.channels.len(),
                c.channels.len()
            ));
        }
    }
    Ok(())
}

fn sampling_interval(c: &Comparison) -> f64 {
    let n = c.time.len();
    (c.time[n - 1] - c.time[0]) / (n - 1) as f64
}

fn text(e: impl Display) -> String {
    e.to_string()
}

/// A tick label rounded to the axis' resolution, without trailing zeros or "-0".
fn tick_label(value: f64, span: f64) -> String {
    let decimals = if span > 0.0 && span.is_finite() {
        (2.0 - span.log10().floor()).clamp(0.0, 12.0) as usize
    } else {
        3
    };
    let label = format!("{value:.decimals$}");
    let label = if label.contains('.') {
        label.trim_end_matches('0').trim_end_matches('.')
    } else {
        &label
    };
    if label.trim_start_matches('-').chars().all(|ch| ch == '0') {
        "0".to_owned()
    } else {
        label.to_owned()
    }
}

fn percent(value: f64) -> String {
    if value.is_finite() {
        format!("{value:.2} %")
    } else {
        "n/a".to_owned()
    }
}

/// (low, high) of the finite values, widened by `pad` of the span on each side; (-1, 1) if
/// there are none, and a unit span around a constant.
fn padded_range(values: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    if hi - lo <= f64::EPSILON * lo.abs().max(1.0) {
        return (lo - 0.5, hi + 0.5);
    }
    let margin = pad * (hi - lo);
    (lo - margin, hi + margin)
}

fn points<'a>(
    x: &'a [f64],
    y: impl IntoIterator<Item = f64> + 'a,
) -> impl Iterator<Item = (f64, f64)> + 'a {
    x.iter()
        .copied()
        .zip(y)
        .filter(|(x, y)| x.is_finite() && y.is_finite())
}

enum KeyItem<'a> {
    Line(RGBColor, &'a str),
    Area(RGBColor, f64, &'a str),
    Note(&'a str),
}

/// The key strip under the title, shared by all panels. Areas are drawn as polygons so that
/// the only shaded rectangles in the picture are the spans they stand for.
fn draw_key(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    items: &[KeyItem<'_>],
    left: i32,
) -> Result<(), String> {
    let font = (FONT, 15).into_font();
    let label_style = TextStyle::from(font.clone()).pos(Pos::new(HPos::Left, VPos::Center));
    let (_, height) = area.dim_in_pixel();
    let y = height as i32 / 2;
    let mut x = left;
    for item in items {
        let label = match item {
            KeyItem::Line(colour, label) => {
                area.draw(&PathElement::new(
                    vec![(x, y), (x + 28, y)],
                    colour.stroke_width(2),
                ))
                .map_err(text)?;
                label
            }
            KeyItem::Area(colour, opacity, label) => {
                let swatch = vec![(x, y - 7), (x + 28, y - 7), (x + 28, y + 7), (x, y + 7)];
                area.draw(&Polygon::new(swatch, colour.mix(*opacity).filled()))
                    .map_err(text)?;
                label
            }
            KeyItem::Note(label) => label,
        };
        area.draw(&Text::new(
            label.to_string(),
            (x + 36, y),
            label_style.clone(),
        ))
        .map_err(text)?;
        let (width, _) = area.estimate_text_size(label, &label_style).map_err(text)?;
        x += 36 + width as i32 + 36;
    }
    Ok(())
}

fn draw_time_view(c: &Comparison, title: &str) -> Result<String, String> {
    let mut svg = String::new();
    let channels = c.channels.len();
    {
        let size = view_size(TIME_VIEW_SIZE, channels, TIME_PANEL_HEIGHT);
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(text)?;
        let root = root.titled(title, (FONT, 24)).map_err(text)?;
        let (key, panels) = root.split_vertically(30);
        let transient = format!(
            "transient (first {:.1} s, not scored)",
            transient_duration(c)
        );
        let mut items = vec![
            KeyItem::Line(MEASURED, "measured"),
            KeyItem::Line(PREDICTED, "predicted"),
            KeyItem::Area(BAND, BAND_OPACITY, "prediction ± 3σ"),
            KeyItem::Line(RESIDUAL, "residual (measured − predicted)"),
            KeyItem::Area(FAILING, FAILING_OPACITY, "failing window"),
        ];
        if c.first > 0 {
            items.push(KeyItem::Area(TRANSIENT, TRANSIENT_OPACITY, &transient));
        }
        draw_key(&key, &items, PANEL_LEFT as i32 + 10)?;
        // Only the bottom panel carries the time axis; it gets that room on top of the same
        // plotting height as the others.
        let (_, height) = panels.dim_in_pixel();
        let panel_height = (height - TIME_AXIS_HEIGHT) / channels as u32;
        let mut rest = panels;
        for channel in 0..channels {
            let last = channel + 1 == channels;
            if last {
                draw_channel(c, channel, &rest, true)?;
            } else {
                let (area, below) = rest.split_vertically(panel_height);
                draw_channel(c, channel, &area, false)?;
                rest = below;
            }
        }
        root.present().map_err(text)?;
    }
    Ok(svg)
}

const PANEL_LEFT: u32 = 80;
const TIME_AXIS_HEIGHT: u32 = 45;

fn transient_duration(c: &Comparison) -> f64 {
    let last = c.time.len() - 1;
    c.time[c.first.min(last)] - c.time[0]
}

fn draw_channel(
    c: &Comparison,
    channel: usize,
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    with_time_axis: bool,
) -> Result<(), String> {
    let panel = ChannelPanel::of(c, channel);
    let mut chart = ChartBuilder::on(area)
        .caption(channel_caption(c, channel, &panel.name), (FONT, 17))
        .margin_left(10)
        .margin_right(24)
        .margin_top(2)
        .margin_bottom(4)
        .x_label_area_size(if with_time_axis { TIME_AXIS_HEIGHT } else { 0 })
        .y_label_area_size(PANEL_LEFT)
        .build_cartesian_2d(panel.t0..panel.t1, panel.lo..panel.hi)
        .map_err(text)?;
    let time_label = |t: &f64| tick_label(*t, panel.t1 - panel.t0);
    let value_label = |a: &f64| tick_label(*a, panel.hi - panel.lo);
    let mut mesh = chart.configure_mesh();
    mesh.x_label_formatter(&time_label)
        .y_label_formatter(&value_label)
        .x_labels(21)
        .y_labels(5)
        .max_light_lines(1)
        .bold_line_style(BLACK.mix(0.10))
        .light_line_style(BLACK.mix(0.04))
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .y_desc(quantity_label(&c.channels[channel]));
    if with_time_axis {
        mesh.x_desc("time (s)");
    }
    mesh.draw().map_err(text)?;
    draw_spans(&mut chart, c, &panel)?;
    draw_traces(&mut chart, c, channel, &panel)
}

type TimeChart<'a, 'b> =
    ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// What one channel's panel shows: its name, the time span, the residual, the ±3σ band at
/// each sample and the value range that holds them all.
struct ChannelPanel {
    name: String,
    t0: f64,
    t1: f64,
    residual: Vec<f64>,
    band: Vec<f64>,
    lo: f64,
    hi: f64,
}

impl ChannelPanel {
    fn of(c: &Comparison, channel: usize) -> Self {
        let n = c.time.len();
        let measured = &c.measured[channel];
        let predicted = &c.predicted[channel];
        let residual = c.residual(channel);
        // ±3σ at each sample: the noise σ, or the corrector's predictive σ where the twin has
        // one.
        let band: Vec<f64> = (0..n)
            .map(|k| 3.0 * c.sd_at(channel, k))
            .map(|b| if b.is_finite() { b } else { 0.0 })
            .collect();
        let (lo, hi) = padded_range(
            measured.iter().chain(&residual).copied().chain(
                predicted
                    .iter()
                    .zip(&band)
                    .flat_map(|(p, b)| [p - b, p + b]),
            ),
            0.04,
        );
        ChannelPanel {
            name: c.channels[channel].name(),
            t0: c.time[0],
            t1: c.time[n - 1],
            residual,
            band,
            lo,
            hi,
        }
    }
}

/// The panel's caption: the channel, its NMSE and the failing windows it is out of band in.
fn channel_caption(c: &Comparison, channel: usize, name: &str) -> String {
    let windows_here = c
        .failing_windows
        .iter()
        .filter(|w| w.channels.iter().any(|ch| ch == name))
        .count();
    let mut caption = format!("{name} — NMSE {}", percent(c.nmse[channel]));
    if windows_here > 0 {
        caption += &format!(
            " — out of band in {windows_here} window{}",
            if windows_here == 1 { "" } else { "s" }
        );
    }
    caption
}

/// The transient and the failing windows as shaded spans (darker where this channel fails).
fn draw_spans(chart: &mut TimeChart, c: &Comparison, panel: &ChannelPanel) -> Result<(), String> {
    let (t0, t1, lo, hi) = (panel.t0, panel.t1, panel.lo, panel.hi);
    let half_sample = 0.5 * sampling_interval(c);
    if c.first > 0 {
        let end = c.time[c.first.min(c.time.len() - 1)];
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(t0, lo), (end, hi)],
                TRANSIENT.mix(TRANSIENT_OPACITY).filled(),
            )))
            .map_err(text)?;
    }
    for window in &c.failing_windows {
        let opacity = if window.channels.contains(&panel.name) {
            FAILING_OPACITY
        } else {
            FAILING_ELSEWHERE_OPACITY
        };
        let span = [
            ((window.start - half_sample).max(t0), lo),
            ((window.end + half_sample).min(t1), hi),
        ];
        chart
            .draw_series(std::iter::once(Rectangle::new(
                span,
                FAILING.mix(opacity).filled(),
            )))
            .map_err(text)?;
    }
    Ok(())
}

/// The prediction's ±3σ band, then the measured, predicted and residual traces.
fn draw_traces(
    chart: &mut TimeChart,
    c: &Comparison,
    channel: usize,
    panel: &ChannelPanel,
) -> Result<(), String> {
    let measured = &c.measured[channel];
    let predicted = &c.predicted[channel];
    let band = &panel.band;
    if band.iter().any(|&b| b > 0.0) {
        let upper = points(&c.time, predicted.iter().zip(band).map(|(p, b)| p + b));
        let lower: Vec<(f64, f64)> =
            points(&c.time, predicted.iter().zip(band).map(|(p, b)| p - b)).collect();
        let outline: Vec<(f64, f64)> = upper.chain(lower.into_iter().rev()).collect();
        chart
            .draw_series(std::iter::once(Polygon::new(
                outline,
                BAND.mix(BAND_OPACITY).filled(),
            )))
            .map_err(text)?;
    }
    chart
        .draw_series(LineSeries::new(
            points(&c.time, measured.iter().copied()),
            MEASURED.stroke_width(1),
        ))
        .map_err(text)?;
    chart
        .draw_series(LineSeries::new(
            points(&c.time, predicted.iter().copied()),
            PREDICTED.stroke_width(1),
        ))
        .map_err(text)?;
    chart
        .draw_series(LineSeries::new(
            points(&c.time, panel.residual.iter().copied()),
            RESIDUAL.stroke_width(1),
        ))
        .map_err(text)?;
    Ok(())
}

fn draw_frequency_view(
    c: &Comparison,
    view: &ComparisonResponses,
    excitation: &Channel,
    title: &str,
) -> Result<String, String> {
    let responses = &view.channels;
    let nyquist = 0.5 / view.dt;
    let (lo, hi) = padded_range(
        responses
            .iter()
            .flatten()
            .flat_map(|r| r.magnitude_db.iter().copied()),
        0.05,
    );
    let lo = lo.max(hi - FRF_DEPTH_DB);
    let segments = responses[0][0].segments;
    let segment_len = view.segment_len;

    let mut svg = String::new();
    {
        let size = view_size(FRF_VIEW_SIZE, responses.len(), FRF_PANEL_HEIGHT);
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(text)?;
        let root = root
            .titled(&frequency_view_title(c, excitation, title), (FONT, 24))
            .map_err(text)?;
        let (key, panels) = root.split_vertically(30);
        let method = format!(
            "H1 estimate, Welch: {segment_len}-sample Hann segments, 50 % overlap, {segments} averages, from t = {:.1} s",
            c.time[c.first.min(c.time.len() - 1)]
        );
        draw_key(
            &key,
            &[
                KeyItem::Line(MEASURED, "measured"),
                KeyItem::Line(PREDICTED, "predicted"),
                KeyItem::Note(&method),
            ],
            PANEL_LEFT as i32 + 10,
        )?;
        let input_unit = unit_label(excitation);
        for (i, area) in panels.split_evenly((1, responses.len())).iter().enumerate() {
            let axes = FrequencyAxes {
                nyquist,
                lo,
                hi,
                input_unit,
            };
            draw_frequency_panel(area, &c.channels[i], &responses[i], &axes)?;
        }
        root.present().map_err(text)?;
    }
    Ok(svg)
}

/// The view's title: what drives the structure and what responds.
fn frequency_view_title(c: &Comparison, excitation: &Channel, title: &str) -> String {
    let what = match excitation {
        Channel::Excitation(::structure::channel::ExcitationKind::GroundAcc) => {
            "ground acceleration"
        }
        _ => "force",
    };
    let responses_are = if c
        .channels
        .iter()
        .all(|ch| ch.quantity() == Quantity::Acceleration)
    {
        "floor acceleration"
    } else {
        "measured channel"
    };
    format!("{title} — frequency response, {what} → {responses_are}")
}

/// The axes every panel of the frequency view shares: 0 to Nyquist, the dB range, the
/// excitation's unit.
struct FrequencyAxes<'a> {
    nyquist: f64,
    lo: f64,
    hi: f64,
    input_unit: &'a str,
}

/// One channel's panel: the measured and predicted |H| in dB, clamped at the range's floor.
fn draw_frequency_panel(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    channel: &Channel,
    responses: &[FrequencyResponse; 2],
    axes: &FrequencyAxes,
) -> Result<(), String> {
    let (nyquist, lo, hi) = (axes.nyquist, axes.lo, axes.hi);
    let frequency_label = |f: &f64| tick_label(*f, nyquist);
    let db_label = |db: &f64| tick_label(*db, 1000.0);
    let mut chart = ChartBuilder::on(area)
        .caption(channel.name(), (FONT, 17))
        .margin_left(10)
        .margin_right(20)
        .margin_bottom(4)
        .x_label_area_size(TIME_AXIS_HEIGHT)
        .y_label_area_size(PANEL_LEFT)
        .build_cartesian_2d(0.0..nyquist, lo..hi)
        .map_err(text)?;
    chart
        .configure_mesh()
        .x_label_formatter(&frequency_label)
        .y_label_formatter(&db_label)
        .x_labels(8)
        .y_labels(8)
        .max_light_lines(1)
        .bold_line_style(BLACK.mix(0.10))
        .light_line_style(BLACK.mix(0.04))
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .x_desc("frequency (Hz)")
        .y_desc(format!(
            "|H| (dB re 1 ({})/{})",
            unit_label(channel),
            axes.input_unit
        ))
        .draw()
        .map_err(text)?;
    for (response, colour) in responses.iter().zip([MEASURED, PREDICTED]) {
        let clamped = response.magnitude_db.iter().map(|db| db.max(lo));
        let line = points(&response.frequency, clamped);
        chart
            .draw_series(LineSeries::new(line, colour.stroke_width(1)))
            .map_err(text)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests;
