//! The plot of `twin control` (the reference paper's Figs 16–18): per floor, the frequency
//! response from the excitation force to the acceleration (left) and the acceleration's time
//! history (right), passive and under each design (and the gain schedule); the contact
//! initiations as vertical lines under the time histories, one row per run.

use plotters::prelude::*;

use super::palette;
use crate::evaluation::frf::FrequencyResponse;
use crate::workflows::control::ControlOutcome;

const FONT: &str = "sans-serif";
const WIDTH: u32 = 1500;
const ROW: u32 = 260;
const COLOURS: [RGBColor; 4] = [
    palette::BLUE,
    palette::VERMILION,
    palette::GREEN,
    palette::ORANGE,
];

fn text(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// The panels' grid and axis labels.
fn draw_mesh<DB: DrawingBackend>(
    chart: &mut ChartContext<
        '_,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
    x: &str,
    y: &str,
) -> Result<(), String> {
    chart
        .configure_mesh()
        .x_desc(x)
        .y_desc(y)
        .label_style((FONT, 12))
        .max_light_lines(1)
        .bold_line_style(BLACK.mix(0.10))
        .light_line_style(BLACK.mix(0.04))
        .draw()
        .map_err(text)
}

/// One line of the plot: its label, colour, accelerations (record rate) and frequency
/// responses per floor.
struct Run<'a> {
    label: String,
    colour: RGBColor,
    acc: &'a [Vec<f64>],
    frf: &'a [Option<FrequencyResponse>],
    contacts: Vec<f64>,
}

/// The plot's lines: the passive run, each design that ran, the gain schedule.
fn runs_of(outcome: &ControlOutcome) -> Vec<Run<'_>> {
    let mut runs = vec![Run {
        label: format!("passive ({} contacts)", outcome.report.passive.contacts),
        colour: palette::GREY,
        acc: &outcome.passive.acc,
        frf: &outcome.passive_frf,
        contacts: outcome.report.passive.contact_times.clone(),
    }];
    let mut c = 0;
    let designs = outcome.report.designs.iter().zip(&outcome.designs);
    for ((d, r), frf) in designs.zip(&outcome.design_frfs) {
        if let (Some(r), Some(frf)) = (r, frf) {
            runs.push(Run {
                label: format!("LQR q = {} ({} contacts)", d.design.q, d.contacts),
                colour: COLOURS[c % COLOURS.len()],
                acc: &r.acc,
                frf,
                contacts: d.contact_times.clone(),
            });
            c += 1;
        }
    }
    if let (Some(s), Some(r), Some(frf)) = (
        &outcome.report.schedule,
        &outcome.scheduled,
        &outcome.scheduled_frf,
    ) {
        runs.push(Run {
            label: format!(
                "scheduled q = {} / {} ({} contacts)",
                s.q_low, s.q_high, s.contacts
            ),
            colour: palette::DARK_GREY,
            acc: &r.acc,
            frf,
            contacts: s.contact_times.clone(),
        });
    }
    runs
}

/// The record's time axis: its samples' times and the last (at least one interval).
struct Axis {
    dt: f64,
    time: Vec<f64>,
    t_end: f64,
}

type Area<'a> = DrawingArea<SVGBackend<'a>, plotters::coord::Shift>;

/// The key: each run's colour and label in a row.
fn draw_key(key: &Area, runs: &[Run]) -> Result<(), String> {
    let mut x = 80;
    for run in runs {
        key.draw(&PathElement::new(
            vec![(x, 20), (x + 30, 20)],
            run.colour.stroke_width(2),
        ))
        .map_err(text)?;
        key.draw(&Text::new(
            run.label.clone(),
            (x + 36, 12),
            (FONT, 14).into_font(),
        ))
        .map_err(text)?;
        x += 40 + 8 * run.label.len() as i32;
    }
    Ok(())
}

/// Floor `floor`'s frequency response from the force to its acceleration, every run's.
fn draw_frf_panel(panel: &Area, runs: &[Run], axis: &Axis, floor: usize) -> Result<(), String> {
    let frfs: Vec<&Option<FrequencyResponse>> = runs.iter().map(|r| &r.frf[floor]).collect();
    let (lo, hi) = frfs
        .iter()
        .copied()
        .flatten()
        .flat_map(|h| h.magnitude_db.iter().copied())
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    let (lo, hi) = if lo.is_finite() {
        ((hi - 80.0).max(lo) - 2.0, hi + 3.0)
    } else {
        (-1.0, 1.0)
    };
    let nyquist = 0.5 / axis.dt;
    let mut chart = ChartBuilder::on(panel)
        .caption(
            format!("floor {}: force → acceleration", floor + 1),
            (FONT, 15),
        )
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(55)
        .build_cartesian_2d(0.0..nyquist.min(30.0), lo..hi)
        .map_err(text)?;
    draw_mesh(&mut chart, "frequency (Hz)", "|H| (dB re 1 (m/s²)/N)")?;
    for (run, h) in runs.iter().zip(frfs) {
        if let Some(h) = h {
            let pts = h
                .frequency
                .iter()
                .zip(&h.magnitude_db)
                .filter(|(f, m)| **f <= 30.0 && m.is_finite())
                .map(|(f, m)| (*f, m.max(lo)));
            chart
                .draw_series(LineSeries::new(pts, run.colour.stroke_width(1)))
                .map_err(text)?;
        }
    }
    Ok(())
}

/// Floor `floor`'s acceleration against time, every run's.
fn draw_time_panel(panel: &Area, runs: &[Run], axis: &Axis, floor: usize) -> Result<(), String> {
    let peak = runs
        .iter()
        .flat_map(|r| r.acc[floor].iter())
        .fold(0.0f64, |m, v| m.max(v.abs()))
        .max(1e-12)
        * 1.05;
    let mut chart = ChartBuilder::on(panel)
        .caption(format!("floor {}: acceleration", floor + 1), (FONT, 15))
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(55)
        .build_cartesian_2d(0.0..axis.t_end, -peak..peak)
        .map_err(text)?;
    draw_mesh(&mut chart, "time (s)", "m/s²")?;
    for run in runs {
        let pts = axis
            .time
            .iter()
            .zip(run.acc[floor].iter())
            .map(|(t, a)| (*t, *a));
        chart
            .draw_series(LineSeries::new(pts, run.colour.mix(0.8).stroke_width(1)))
            .map_err(text)?;
    }
    Ok(())
}

/// Contact initiations: one row of ticks per run (the paper's vertical lines).
fn draw_contacts(area: &Area, runs: &[Run], axis: &Axis) -> Result<(), String> {
    let t_end = axis.t_end;
    let rows_n = runs.len() as f64;
    let mut chart = ChartBuilder::on(area)
        .caption("contact initiations (drift crossing the gap)", (FONT, 15))
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(55)
        .build_cartesian_2d(0.0..t_end, 0.0..rows_n)
        .map_err(text)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_y_axis()
        .x_desc("time (s)")
        .label_style((FONT, 12))
        .draw()
        .map_err(text)?;
    for (i, run) in runs.iter().enumerate() {
        let y = rows_n - i as f64 - 1.0;
        chart
            .draw_series(std::iter::once(Text::new(
                run.label.clone(),
                (0.005 * t_end, y + 0.75),
                (FONT, 11).into_font().color(&run.colour),
            )))
            .map_err(text)?;
        for &t in &run.contacts {
            chart
                .draw_series(LineSeries::new(
                    [(t, y + 0.1), (t, y + 0.9)],
                    run.colour.stroke_width(2),
                ))
                .map_err(text)?;
        }
    }
    Ok(())
}

/// The SVG text of the plot.
pub fn plot_control(outcome: &ControlOutcome, title: &str) -> Result<String, String> {
    let runs = runs_of(outcome);
    let dt = outcome.dt;
    let time: Vec<f64> = (0..outcome.force.len()).map(|k| k as f64 * dt).collect();
    let t_end = time.last().copied().unwrap_or(1.0).max(dt);
    let axis = Axis { dt, time, t_end };
    // A row per floor of the structure (the paper's rig: three).
    let floors = outcome.passive.acc.len();
    let contact_rows = runs.len() as u32 * 16 + 60;
    let height = 90 + floors as u32 * ROW + contact_rows;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (WIDTH, height)).into_drawing_area();
        root.fill(&WHITE).map_err(text)?;
        let root = root.titled(title, (FONT, 22)).map_err(text)?;
        let (key, rest) = root.split_vertically(40);
        draw_key(&key, &runs)?;
        let (rows, bottom) = rest.split_vertically(floors as u32 * ROW);
        let panels = rows.split_evenly((floors, 2));
        for floor in 0..floors {
            draw_frf_panel(&panels[2 * floor], &runs, &axis, floor)?;
            draw_time_panel(&panels[2 * floor + 1], &runs, &axis, floor)?;
        }
        draw_contacts(&bottom, &runs, &axis)?;
        root.present().map_err(text)?;
    }
    Ok(svg)
}
