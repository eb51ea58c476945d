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
/// at that sample in the shortest text that reads back to the same `f64` (ryu's: `0.0123`,
/// `1.5e-7`, `NaN`): what `twin compare --predictions` writes. Every column as long as `time`.
///
/// The text is formatted in blocks of [`CSV_BLOCK_ROWS`] rows, each block's rows shared among
/// the cores (formatting a float is most of the work: about 150 instructions a value with ryu,
/// 1,100 with `{:e}`)
/// and written in order, so the file is the same on any number of cores and its text is never
/// held whole (a 20-storey, 131,072-sample prediction is 60 MB of it).
pub fn columns_csv(
    out: &mut impl std::io::Write,
    time: &[f64],
    columns: &[(String, &[f64])],
) -> std::io::Result<()> {
    let mut header = b"time".to_vec();
    for (name, _) in columns {
        header.push(b',');
        header.extend_from_slice(name.as_bytes());
    }
    header.push(b'\n');
    out.write_all(&header)?;
    let threads = crate::parallel::cores();
    // Rows a thread formats at least: below, a thread costs more than it saves.
    const ROWS_PER_THREAD: usize = 256;
    let mut first = 0;
    while first < time.len() {
        let end = (first + CSV_BLOCK_ROWS).min(time.len());
        let parts = (end - first)
            .div_ceil(ROWS_PER_THREAD)
            .clamp(1, threads.max(1));
        let chunk = (end - first).div_ceil(parts);
        let ranges: Vec<(usize, usize)> = (first..end)
            .step_by(chunk)
            .map(|a| (a, (a + chunk).min(end)))
            .collect();
        let texts = if ranges.len() == 1 {
            vec![csv_rows(time, columns, ranges[0])]
        } else {
            crate::parallel::on_threads(&ranges, ranges.len(), |&r| csv_rows(time, columns, r))
        };
        for text in texts {
            out.write_all(&text)?;
        }
        first = end;
    }
    out.flush()
}

/// Rows [`columns_csv`] formats and writes at a time.
const CSV_BLOCK_ROWS: usize = 8192;

/// Rows `first..end` of [`columns_csv`]'s table as text.
fn csv_rows(time: &[f64], columns: &[(String, &[f64])], (first, end): (usize, usize)) -> Vec<u8> {
    use std::io::Write;
    let mut text = Vec::with_capacity((end - first) * (columns.len() + 1) * 24);
    let mut buffer = ryu::Buffer::new();
    for (k, t) in time.iter().enumerate().take(end).skip(first) {
        // Writing into a Vec cannot fail.
        let _ = write!(text, "{t}");
        for (_, values) in columns {
            text.push(b',');
            text.extend_from_slice(buffer.format(values[k]).as_bytes());
        }
        text.push(b'\n');
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table in blocks over the cores is the table row after row: across a block's end
    /// and with rows left over after the threads' shares.
    #[test]
    fn columns_csv_is_the_table_row_after_row() {
        let rows = CSV_BLOCK_ROWS + 777;
        let time: Vec<f64> = (0..rows).map(|k| k as f64 / 51.2).collect();
        let mut a: Vec<f64> = (0..rows).map(|k| (k as f64 * 0.37).sin() * 1e-3).collect();
        let b: Vec<f64> = (0..rows).map(|k| -(k as f64).sqrt() / 7.0).collect();
        // Values far from 1 and not finite: each read back as it was.
        a[1] = 1.5e-300;
        a[2] = -7.25e21;
        a[3] = f64::NAN;
        a[4] = f64::INFINITY;
        let columns = vec![("acc1".to_owned(), a.as_slice()), ("acc2".into(), &b[..])];
        let mut text = Vec::new();
        columns_csv(&mut text, &time, &columns).unwrap();
        let text = String::from_utf8(text).unwrap();
        let mut lines = text.lines();
        assert_eq!(lines.next(), Some("time,acc1,acc2"));
        let same = |got: &str, want: f64| {
            let got: f64 = got.parse().unwrap();
            got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan())
        };
        for k in 0..rows {
            let line = lines.next().unwrap_or_else(|| panic!("row {k} missing"));
            let fields: Vec<&str> = line.split(',').collect();
            assert_eq!(fields.len(), 3, "row {k}: {line}");
            assert_eq!(fields[0], format!("{}", time[k]), "row {k}");
            assert!(
                same(fields[1], a[k]) && same(fields[2], b[k]),
                "row {k}: {line}"
            );
        }
        assert_eq!(lines.next(), None);
    }
}
