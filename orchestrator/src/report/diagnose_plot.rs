//! The diagnosis plot: per measured channel, the residual before and after the chosen action with the
//! failing windows shaded; then the evidence: the storey shear the twin misses against the
//! storey's drift, with the fitted effect's force (for a contact, the kink at the gap).

use plotters::prelude::*;

use crate::report::palette;
use crate::workflows::diagnose::{Action, DiagnoseError, Diagnosis, EffectKind, Kind, Result};

const BEFORE: RGBColor = palette::VERMILION;
const AFTER: RGBColor = palette::BLUE;
const FAILING: RGBColor = palette::RED;
const EFFECT: RGBColor = palette::GREEN;
const SIZE: (u32, u32) = (1400, 1200);

fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = 0.05 * (hi - lo).max(1e-12);
    (lo - pad, hi + pad)
}

type Area<'a> = DrawingArea<SVGBackend<'a>, plotters::coord::Shift>;
type Chart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

fn err(e: &dyn std::fmt::Display) -> DiagnoseError {
    DiagnoseError::Plot(format!("drawing the diagnosis plot: {e}"))
}

/// Draw the plot of `d` as an SVG document: a row of residuals per channel above, the
/// evidence below.
pub fn draw_diagnosis(d: &Diagnosis) -> Result<String> {
    if d.series.time.len() < 2 {
        return Err(DiagnoseError::Plot(
            "the diagnosis plot needs at least 2 samples".into(),
        ));
    }
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let root = root
            .titled(&title(d), ("sans-serif", 22))
            .map_err(|e| err(&e))?;
        let (top, bottom) = root.split_vertically(SIZE.1 * 62 / 100);
        let rows = top.split_evenly((d.series.measured.len().max(1), 1));
        for (f, area) in rows.iter().enumerate().take(d.series.measured.len()) {
            draw_residuals(area, d, f)?;
        }
        draw_evidence(&bottom, d)?;
        root.present().map_err(|e| err(&e))?;
    }
    Ok(svg)
}

/// The record, the action and what it names.
fn title(d: &Diagnosis) -> String {
    format!(
        "{} — action: {}{}",
        d.record,
        d.action.name(),
        d.effect
            .as_ref()
            .map(|e| format!(" ({})", e.name.label))
            .or_else(|| d.sensor.as_ref().map(|x| format!(
                " ({} on floor {}: gain {:.3}, offset {:.3e}, drift {:.3e})",
                x.channel, x.floor, x.gain, x.offset, x.drift
            )))
            .unwrap_or_default()
    )
}

/// Channel `f`'s row: its residual before and after the action, its failing windows shaded.
fn draw_residuals(area: &Area, d: &Diagnosis, f: usize) -> Result<()> {
    let s = &d.series;
    let t = &s.time[s.first..];
    let after_label = match d.action {
        Action::AddPhysics => "residual after adding the effect",
        Action::Recalibrate => "residual after recalibration",
        Action::SensorFault => "residual with the sensor fault modelled",
        _ => "residual (unchanged)",
    };
    let floor = s.floors.get(f).copied().unwrap_or(f + 1);
    let channel = d.channels.get(f).map(String::as_str).unwrap_or("?");
    let before: Vec<f64> = (s.first..s.time.len())
        .map(|k| s.measured[f][k] - s.before[f][k])
        .collect();
    let after: Vec<f64> = (s.first..s.time.len())
        .map(|k| s.measured[f][k] - s.after[f][k])
        .collect();
    let (lo, hi) = range(before.iter().chain(&after).copied());
    let mut chart = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(28)
        .y_label_area_size(70)
        .caption(
            format!(
                "{channel} (floor {}): NMSE {:.3} % → {:.3} %",
                floor, d.nmse_before[f], d.nmse_after[f]
            ),
            ("sans-serif", 16),
        )
        .build_cartesian_2d(t[0]..t[t.len() - 1], lo..hi)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc(format!("residual ({})", si_unit(d, channel)))
        .light_line_style(WHITE)
        .draw()
        .map_err(|e| err(&e))?;
    for w in d
        .failing_windows
        .iter()
        .filter(|w| w.floors.contains(&floor))
    {
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(w.start, lo), (w.end, hi)],
                FAILING.mix(0.15).filled(),
            )))
            .map_err(|e| err(&e))?;
    }
    chart
        .draw_series(LineSeries::new(
            t.iter().copied().zip(before.iter().copied()),
            BEFORE.stroke_width(1),
        ))
        .map_err(|e| err(&e))?
        .label("residual before")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BEFORE));
    chart
        .draw_series(LineSeries::new(
            t.iter().copied().zip(after.iter().copied()),
            AFTER.stroke_width(1),
        ))
        .map_err(|e| err(&e))?
        .label(after_label)
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], AFTER));
    if f == 0 {
        legend(&mut chart)?;
    }
    Ok(())
}

/// The SI unit of `channel`'s quantity (the record's values are read into SI units).
fn si_unit(d: &Diagnosis, channel: &str) -> &'static str {
    match d.sensing.iter().find(|x| x.channel == channel) {
        Some(x) if x.quantity == "velocity" => "m/s",
        Some(x) if x.quantity == "displacement" => "m",
        _ => "m/s²",
    }
}

/// The evidence panel's storey and kind: the winning effect's storey (or floor), else the
/// storey the localisation points at.
fn evidence_site(d: &Diagnosis) -> (usize, EffectKind) {
    let storeys = d.series.drift.len().max(1);
    match &d.effect {
        Some(e) => (
            e.name
                .location
                .last()
                .copied()
                .unwrap_or(1)
                .clamp(1, storeys),
            e.name.kind,
        ),
        None => {
            let n = d
                .localisation
                .strongest
                .rsplit(' ')
                .next()
                .and_then(|x| x.parse().ok())
                .unwrap_or(1usize)
                .clamp(1, storeys);
            (n, EffectKind::Contact)
        }
    }
}

/// The evidence panel's axis label and caption.
fn evidence_labels(d: &Diagnosis, storey: usize, what: EffectKind) -> (String, String) {
    if let Some(a) = d.series.evidence_axis.as_ref() {
        (
            a.label.clone(),
            format!(
                "evidence: storey {storey} shear the twin misses (Σ mⱼ·residualⱼ above it) \
                 against the {}",
                a.label
            ),
        )
    } else if what == Kind::Friction {
        (
            format!("velocity of floor {storey} is not drawn; drift of storey {storey} (m)"),
            format!("evidence: force the twin misses at storey {storey} against its drift"),
        )
    } else {
        (
            format!("drift of storey {storey} (m)"),
            format!(
                "evidence: storey {storey} shear the twin misses (Σ mⱼ·residualⱼ above it) \
                 against the storey's drift"
            ),
        )
    }
}

/// The evidence: the storey shear the twin misses against the storey's drift (or the
/// evidence axis), with the fitted effect's force.
fn draw_evidence(bottom: &Area, d: &Diagnosis) -> Result<()> {
    let s = &d.series;
    let (storey, what) = evidence_site(d);
    let i = storey - 1;
    let axis = s.evidence_axis.as_ref();
    let x: Vec<f64> = match axis {
        Some(a) => a.values[s.first..].to_vec(),
        None => s.drift[i][s.first..].to_vec(),
    };
    let y: Vec<f64> = s.missing_shear[i][s.first..].to_vec();
    let (xlo, xhi) = range(x.iter().copied());
    let mut ys: Vec<f64> = y.clone();
    if let Some(fe) = &s.effect_force {
        ys.extend(fe[s.first..].iter().map(|v| -v));
    }
    let (ylo, yhi) = range(ys.into_iter());
    let (x_desc, caption) = evidence_labels(d, storey, what);
    let mut chart = ChartBuilder::on(bottom)
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(70)
        .caption(caption, ("sans-serif", 16))
        .build_cartesian_2d(xlo..xhi, ylo..yhi)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc("missing shear (N)")
        .light_line_style(WHITE)
        .draw()
        .map_err(|e| err(&e))?;
    chart
        .draw_series(
            x.iter()
                .zip(&y)
                .map(|(a, b)| Circle::new((*a, *b), 2, BEFORE.mix(0.5).filled())),
        )
        .map_err(|e| err(&e))?
        .label(if s.effect_force.is_some() {
            "storey shear the linear part misses, along the fitted model"
        } else {
            "missing shear, twin as given"
        })
        .legend(|(x, y)| Circle::new((x + 10, y), 3, BEFORE.filled()));
    if let (Some(fe), Some(e)) = (&s.effect_force, &d.effect) {
        if what != Kind::Friction {
            let mut pts: Vec<(f64, f64)> = x
                .iter()
                .copied()
                .zip(fe[s.first..].iter().map(|v| -v))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            let label = format!("fitted {} force (restoring, sign flipped)", e.name.label);
            if axis.is_some_and(|a| !a.curve) {
                // A force of both drift and rate is no curve of either: its points.
                chart
                    .draw_series(
                        pts.into_iter()
                            .map(|p| Circle::new(p, 2, EFFECT.mix(0.6).filled())),
                    )
                    .map_err(|e| err(&e))?
                    .label(label)
                    .legend(|(x, y)| Circle::new((x + 10, y), 3, EFFECT.filled()));
            } else {
                chart
                    .draw_series(LineSeries::new(pts, EFFECT.stroke_width(3)))
                    .map_err(|e| err(&e))?
                    .label(label)
                    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], EFFECT));
            }
        }
    }
    legend(&mut chart)
}

/// The series' labels in a box on white.
fn legend<'a, 'b: 'a>(chart: &mut Chart<'a, 'b>) -> Result<()> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| err(&e))?;
    Ok(())
}
