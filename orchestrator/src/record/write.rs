//! Writing a record as the measurement CSV `data/` has (times to 1 µs, values to 9 significant
//! digits), and a prediction's columns (every value to its shortest round-trip form).

use super::Measurement;

/// A value as the CSV writes it (9 significant digits), read back.
pub(crate) fn round9(x: f64) -> f64 {
    format_g9(x).parse().unwrap_or(x)
}

/// A time as the CSV writes it (to 1 µs), read back.
pub(crate) fn round_time(t: f64) -> f64 {
    format!("{t:.6}").parse().unwrap_or(t)
}

/// `%.9g`: 9 significant digits, trailing zeros removed, exponent form below 1e-4 or from 1e9.
pub fn format_g9(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return if x == 0.0 { "0".into() } else { format!("{x}") };
    }
    let e = format!("{x:.8e}");
    let (mantissa, exponent) = e.split_once('e').unwrap_or((&e, "0"));
    let exponent: i32 = exponent.parse().unwrap_or(0);
    let trim = |s: &str| -> String {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s.to_string()
        }
    };
    if !(-4..9).contains(&exponent) {
        let sign = if exponent < 0 { '-' } else { '+' };
        format!("{}e{sign}{:02}", trim(mantissa), exponent.abs())
    } else {
        let decimals = (8 - exponent) as usize;
        trim(&format!("{x:.decimals$}"))
    }
}

/// The record as CSV text: `time`, the excitation, the responses (the paper's
/// `time,force,acc1,acc2,acc3`), then `control` when the record has a control force. Each
/// channel in its own unit: SI ones as the bare name, others as `name (unit)` (`acc3 (g)`,
/// `vel1 (mm/s)`) with the values in that unit.
pub fn csv_text(m: &Measurement) -> String {
    let control = m.extra.get("control").filter(|c| c.len() == m.len());
    let channels: Vec<(&[f64], f64)> = m
        .channels()
        .map(|s| (s.values.as_slice(), s.unit.to_si()))
        .collect();
    let mut text = String::with_capacity(16 * (channels.len() + 2) * (m.len() + 1));
    text.push_str("time");
    for signal in m.channels() {
        text.push(',');
        if signal.unit == signal.channel.quantity().si() {
            text.push_str(&signal.channel.name());
        } else {
            text.push_str(&format!(
                "{} ({})",
                signal.channel.name(),
                signal.unit.symbol()
            ));
        }
    }
    text.push_str(if control.is_some() {
        ",control\n"
    } else {
        "\n"
    });
    for k in 0..m.len() {
        text.push_str(&format!("{:.6}", m.time[k]));
        for (column, scale) in &channels {
            text.push(',');
            if *scale == 1.0 {
                text.push_str(&format_g9(column[k]));
            } else {
                text.push_str(&format_g9(column[k] / scale));
            }
        }
        if let Some(c) = control {
            text.push(',');
            text.push_str(&format_g9(c[k]));
        }
        text.push('\n');
    }
    text
}

/// Named columns as CSV to `out`: `time` (its shortest round-trip form) then each column's value
/// at that sample in the shortest exponent form that reads back to the same `f64` (`{:e}`): what
/// `twin compare --predictions` writes. Every column as long as `time`. Written as it is
/// formatted, through a buffer (a 20-storey prediction is half a megabyte of text).
pub fn columns_csv(
    out: &mut impl std::io::Write,
    time: &[f64],
    columns: &[(String, &[f64])],
) -> std::io::Result<()> {
    use std::io::Write;
    let mut w = std::io::BufWriter::with_capacity(1 << 16, out);
    w.write_all(b"time")?;
    for (name, _) in columns {
        write!(w, ",{name}")?;
    }
    w.write_all(b"\n")?;
    for (k, t) in time.iter().enumerate() {
        write!(w, "{t}")?;
        for (_, values) in columns {
            write!(w, ",{:e}", values[k])?;
        }
        w.write_all(b"\n")?;
    }
    w.flush()
}
