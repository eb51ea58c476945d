//! Universal files (`.uff`, `.unv`), dataset 58 ("function at nodal DOF"), ASCII and binary
//! (58b), as measurement systems export FRFs (function type 4) and time responses (type 1).
//!
//! Written here: no maintained Rust crate reads dataset 58. The fixed-column records follow the
//! I-DEAS universal file format: record 6 names the response and reference entity, node and
//! direction; record 7 the ordinate data type (2/4 real single/double, 5/6 complex single/double),
//! the number of points and the (even or uneven) abscissa; records 8–10 each axis's specific data
//! type (8 displacement, 11 velocity, 12 acceleration, 13 excitation force, 17 time, 18
//! frequency), unit exponents and units label; record 12 the values (fixed width in ASCII, raw
//! IEEE floats after record 11 in 58b, in the byte order its header names).
//!
//! Channels: each record's response node and direction, written `<node>:<dir>` (`3:+1`) or
//! `<node>` alone as the key of a [`ColumnMap`], are mapped to a channel; by default the
//! response node i is floor i, its quantity the ordinate's specific data type (acceleration,
//! velocity, displacement) and, in a time file, an excitation force record (type 13) is `force`.
//! Values go to SI by the units label (`g`, `mm/s`, `kN`, … as a CSV header names them; `NONE`
//! or an empty label is SI); a negative direction flips the sign.

use std::path::Path;

use ::structure::channel::{split_unit, Channel, Quantity, Unit};
use rustfft::num_complex::Complex;

use super::frf::{check_frequency, FrfChannel, FrfValues, MeasuredFrf};
use super::{ColumnMap, DataError, Measurement};

/// Whether `path` names a universal file (by its extension).
pub fn is_universal_file(path: &Path) -> bool {
    matches!(
        path.extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref(),
        Some("uff" | "unv")
    )
}

/// One dataset 58 as read.
#[derive(Debug, Clone)]
struct Function {
    /// The line of its record 1 (`58` / `58b`).
    line: u64,
    function_type: i64,
    response_node: i64,
    response_direction: i64,
    reference_node: i64,
    reference_direction: i64,
    abscissa: Vec<f64>,
    /// Real ordinates have a zero imaginary part.
    values: Vec<Complex<f64>>,
    complex: bool,
    abscissa_type: i64,
    ordinate_type: i64,
    ordinate_units: String,
    denominator_type: i64,
    denominator_units: String,
}

/// A file's bytes, walked line by line with binary blocks read by length.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
    line: u64,
}

impl<'a> Cursor<'a> {
    fn next_line(&mut self) -> Option<&'a str> {
        if self.at >= self.bytes.len() {
            return None;
        }
        let rest = &self.bytes[self.at..];
        let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
        self.at += (end + 1).min(rest.len());
        self.line += 1;
        let text = std::str::from_utf8(&rest[..end]).unwrap_or("");
        Some(text.trim_end_matches('\r'))
    }
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let block = self.bytes.get(self.at..self.at + n)?;
        self.at += n;
        self.line += block.iter().filter(|&&b| b == b'\n').count() as u64;
        Some(block)
    }
}

/// Characters `from..to` (1-based columns, inclusive) of a fixed-format line, trimmed.
fn columns(line: &str, from: usize, to: usize) -> &str {
    let start = (from - 1).min(line.len());
    let end = to.min(line.len());
    line.get(start..end).unwrap_or("").trim()
}

fn integer(line: &str, from: usize, to: usize, what: &str) -> Result<i64, String> {
    let field = columns(line, from, to);
    if field.is_empty() {
        return Ok(0);
    }
    field
        .parse()
        .map_err(|_| format!("{what} (columns {from}–{to}) is not an integer: '{field}'"))
}

fn real(field: &str, what: &str) -> Result<f64, String> {
    // Fortran exponents may be written with D.
    field
        .trim()
        .replace(['D', 'd'], "E")
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| format!("{what} is not a finite number: '{}'", field.trim()))
}

/// Read every dataset of a universal file, keeping the 58s.
fn read_functions(path: &Path) -> Result<Vec<Function>, DataError> {
    let bytes = std::fs::read(path).map_err(|e| DataError {
        path: path.to_owned(),
        line: None,
        message: format!("cannot read: {e}"),
    })?;
    let mut cursor = Cursor {
        bytes: &bytes,
        at: 0,
        line: 0,
    };
    let mut functions = Vec::new();
    // A dataset opens with a "-1" line and its number.
    while let Some(line) = cursor.next_line() {
        if line.trim().is_empty() {
            continue;
        }
        let err = |line: u64, message: String| DataError {
            path: path.to_owned(),
            line: Some(line),
            message,
        };
        if line.trim() != "-1" {
            return Err(err(
                cursor.line,
                format!("expected '-1' opening a dataset, found '{}'", line.trim()),
            ));
        }
        let start = cursor.line + 1;
        let header = cursor
            .next_line()
            .ok_or_else(|| err(start, "the file ends after a dataset's '-1'".into()))?;
        let number = columns(header, 1, 6);
        let binary = header
            .get(6..7)
            .is_some_and(|c| c.eq_ignore_ascii_case("b"));
        if number != "58" {
            // Another dataset (units, nodes, …): skipped to its closing "-1".
            if binary {
                return Err(err(
                    start,
                    format!("binary dataset {number}b: only 58b is read"),
                ));
            }
            loop {
                match cursor.next_line() {
                    Some(l) if l.trim() == "-1" => break,
                    Some(_) => {}
                    None => {
                        return Err(err(
                            start,
                            format!("dataset {number} is not closed by '-1'"),
                        ))
                    }
                }
            }
            continue;
        }
        let byte_order = if binary {
            integer(header, 8, 13, "the byte order").map_err(|m| err(start, m))?
        } else {
            0
        };
        let function = read_58(&mut cursor, start, binary, byte_order)
            .map_err(|(line, m)| err(line, format!("dataset 58 at line {start}: {m}")))?;
        functions.push(function);
    }
    if functions.is_empty() {
        return Err(DataError {
            path: path.to_owned(),
            line: None,
            message: "no dataset 58 (function at nodal DOF) in the file".into(),
        });
    }
    Ok(functions)
}

/// How a dataset 58's numbers are laid out (its record 7).
#[derive(Clone, Copy)]
struct Form {
    points: usize,
    complex: bool,
    double: bool,
    /// Evenly spaced abscissae (not written per point).
    even: bool,
    minimum: f64,
    increment: f64,
}

impl Form {
    /// Numbers per point: the ordinate's one or two, and the abscissa when uneven.
    fn per_point(&self) -> usize {
        usize::from(self.complex) + 1 + usize::from(!self.even)
    }
    fn count(&self) -> usize {
        self.points * self.per_point()
    }

    /// The abscissae and ordinates of the numbers read.
    fn points_of(&self, numbers: &[f64]) -> (Vec<f64>, Vec<Complex<f64>>) {
        let per_point = self.per_point();
        let mut abscissa = Vec::with_capacity(self.points);
        let mut values = Vec::with_capacity(self.points);
        for k in 0..self.points {
            let row = &numbers[k * per_point..(k + 1) * per_point];
            let (x, rest) = if self.even {
                (self.minimum + k as f64 * self.increment, row)
            } else {
                (row[0], &row[1..])
            };
            abscissa.push(x);
            values.push(Complex::new(
                rest[0],
                if self.complex { rest[1] } else { 0.0 },
            ));
        }
        (abscissa, values)
    }
}

/// A dataset 58's records 1–11: its DOFs, its data's form and its axes' types and units (a
/// [`Function`] without its data).
fn read_58_header(cursor: &mut Cursor, start: u64) -> Result<(Function, Form), (u64, String)> {
    let mut record = |what: &str| -> Result<(u64, &str), (u64, String)> {
        let line = cursor
            .next_line()
            .ok_or_else(|| (cursor.line, format!("the file ends before {what}")))?;
        Ok((cursor.line, line))
    };
    for i in 1..=5 {
        record(&format!("ID line {i}"))?;
    }
    let (l6, r6) = record("record 6 (the DOF identification)")?;
    let at = |l: u64| move |m: String| (l, m);
    let function_type = integer(r6, 1, 5, "the function type").map_err(at(l6))?;
    let response_node = integer(r6, 42, 51, "the response node").map_err(at(l6))?;
    let response_direction = integer(r6, 52, 55, "the response direction").map_err(at(l6))?;
    let reference_node = integer(r6, 67, 76, "the reference node").map_err(at(l6))?;
    let reference_direction = integer(r6, 77, 80, "the reference direction").map_err(at(l6))?;
    let (l7, r7) = record("record 7 (the data form)")?;
    let ordinate_data_type = integer(r7, 1, 10, "the ordinate data type").map_err(at(l7))?;
    let points = integer(r7, 11, 20, "the number of points").map_err(at(l7))?;
    let even = integer(r7, 21, 30, "the abscissa spacing").map_err(at(l7))? == 1;
    let minimum = real(columns(r7, 31, 43), "the abscissa minimum").map_err(at(l7))?;
    let increment = real(columns(r7, 44, 56), "the abscissa increment").map_err(at(l7))?;
    let mut axis = |what: &str| -> Result<(i64, String), (u64, String)> {
        let (l, r) = record(what)?;
        let kind = integer(r, 1, 10, "the specific data type").map_err(at(l))?;
        // The units label: columns 48–67 (after the axis label at 27–46).
        Ok((kind, columns(r, 48, 67).to_owned()))
    };
    let (abscissa_type, _) = axis("record 8 (the abscissa)")?;
    let (ordinate_type, ordinate_units) = axis("record 9 (the ordinate)")?;
    let (denominator_type, denominator_units) = axis("record 10 (the ordinate's denominator)")?;
    axis("record 11 (the z axis)")?;
    let (complex, double) = match ordinate_data_type {
        2 => (false, false),
        4 => (false, true),
        5 => (true, false),
        6 => (true, true),
        other => {
            return Err((
                l7,
                format!("ordinate data type {other}: only 2, 4 (real) and 5, 6 (complex) are read"),
            ))
        }
    };
    if points < 2 {
        return Err((l7, format!("{points} points; at least 2 are needed")));
    }
    let function = Function {
        line: start,
        function_type,
        response_node,
        response_direction,
        reference_node,
        reference_direction,
        abscissa: Vec::new(),
        values: Vec::new(),
        complex,
        abscissa_type,
        ordinate_type,
        ordinate_units,
        denominator_type,
        denominator_units,
    };
    let form = Form {
        points: points as usize,
        complex,
        double,
        even,
        minimum,
        increment,
    };
    Ok((function, form))
}

/// A 58b dataset's numbers: `form.count()` values of 4 or 8 bytes in the byte order.
fn read_58_binary(
    cursor: &mut Cursor,
    form: Form,
    start: u64,
    byte_order: i64,
) -> Result<Vec<f64>, (u64, String)> {
    let (count, double) = (form.count(), form.double);
    let width = if double { 8 } else { 4 };
    let data_line = cursor.line + 1;
    let block = cursor.take(count * width).ok_or_else(|| {
        (
            data_line,
            format!("the binary data ends before {count} values of {width} bytes"),
        )
    })?;
    let little = match byte_order {
        1 => true,
        2 => false,
        other => {
            return Err((
                start,
                format!("byte order {other}: 1 (little endian) or 2 (big endian)"),
            ))
        }
    };
    Ok(block
        .chunks_exact(width)
        .map(|c| match (double, little) {
            (true, true) => f64::from_le_bytes(c.try_into().unwrap_or([0; 8])),
            (true, false) => f64::from_be_bytes(c.try_into().unwrap_or([0; 8])),
            (false, true) => f32::from_le_bytes(c.try_into().unwrap_or([0; 4])) as f64,
            (false, false) => f32::from_be_bytes(c.try_into().unwrap_or([0; 4])) as f64,
        })
        .collect())
}

/// An ASCII dataset 58's numbers, in fixed widths: 13 (single), 20 (double); an uneven
/// double abscissa is 13 wide.
fn read_58_ascii(cursor: &mut Cursor, form: Form) -> Result<Vec<f64>, (u64, String)> {
    let count = form.count();
    let widths: Vec<usize> = match (form.double, form.even, form.complex) {
        (false, _, _) => vec![13],
        (true, true, _) => vec![20],
        (true, false, false) => vec![13, 20],
        (true, false, true) => vec![13, 20, 20],
    };
    let mut numbers = Vec::with_capacity(count);
    while numbers.len() < count {
        let line = cursor.next_line().ok_or_else(|| {
            (
                cursor.line,
                format!("the file ends after {} of {count} values", numbers.len()),
            )
        })?;
        let l = cursor.line;
        if line.trim() == "-1" {
            return Err((
                l,
                format!(
                    "the dataset closes after {} of {count} values",
                    numbers.len()
                ),
            ));
        }
        let mut at = 0;
        while at < line.trim_end().len() && numbers.len() < count {
            let w = widths[numbers.len() % widths.len()];
            let field = line.get(at..(at + w).min(line.len())).unwrap_or("");
            numbers.push(real(field, &format!("value {}", numbers.len() + 1)).map_err(|m| (l, m))?);
            at += w;
        }
    }
    Ok(numbers)
}

/// The closing "-1" (after binary data, possibly on the same line as the last byte).
fn close_dataset(cursor: &mut Cursor) -> Result<(), (u64, String)> {
    loop {
        match cursor.next_line() {
            Some(l) if l.trim().is_empty() => continue,
            Some(l) if l.trim() == "-1" => return Ok(()),
            Some(l) => {
                return Err((
                    cursor.line,
                    format!("expected '-1' closing the dataset, found '{}'", l.trim()),
                ))
            }
            None => return Err((cursor.line, "the dataset is not closed by '-1'".into())),
        }
    }
}

/// One dataset 58 from its record 1 on (at line `start`): its header, its numbers (binary or
/// ASCII), every one finite, the closing "-1".
fn read_58(
    cursor: &mut Cursor,
    start: u64,
    binary: bool,
    byte_order: i64,
) -> Result<Function, (u64, String)> {
    let (mut function, form) = read_58_header(cursor, start)?;
    let numbers = if binary {
        read_58_binary(cursor, form, start, byte_order)?
    } else {
        read_58_ascii(cursor, form)?
    };
    if let Some(k) = numbers.iter().position(|v| !v.is_finite()) {
        return Err((start, format!("value {} is not finite", k + 1)));
    }
    close_dataset(cursor)?;
    (function.abscissa, function.values) = form.points_of(&numbers);
    Ok(function)
}

/// The quantity of a specific data type: 8 displacement, 11 velocity, 12 acceleration, 13 force.
fn quantity_of(kind: i64) -> Option<Quantity> {
    match kind {
        8 => Some(Quantity::Displacement),
        11 => Some(Quantity::Velocity),
        12 => Some(Quantity::Acceleration),
        9 | 13 => Some(Quantity::Force),
        _ => None,
    }
}

/// The SI factor of a units label for `quantity` (`NONE` or empty: SI).
fn unit_factor(label: &str, quantity: Quantity) -> Result<f64, String> {
    let label = label.trim();
    if label.is_empty() || label.eq_ignore_ascii_case("none") {
        return Ok(1.0);
    }
    let normalised = label.replace("^", "").replace("**", "").replace(' ', "");
    match Unit::parse(&normalised) {
        Some(u) if u.quantity() == quantity => Ok(u.to_si()),
        _ => Err(format!(
            "units label '{label}' is not a unit of {} the twin knows (e.g. {})",
            quantity_name(quantity),
            quantity.si().symbol()
        )),
    }
}

fn quantity_name(q: Quantity) -> &'static str {
    match q {
        Quantity::Acceleration => "acceleration",
        Quantity::Velocity => "velocity",
        Quantity::Displacement => "displacement",
        Quantity::Force => "force",
        Quantity::Time => "time",
    }
}

/// The channel a record's response DOF maps to: the column map's by `<node>:<dir>` or
/// `<node>`, else `<quantity><node>` (`acc3`) for a response and `force` for an excitation.
fn channel_of(f: &Function, map: &ColumnMap) -> Result<(Channel, Option<Unit>), String> {
    let key = format!("{}:{:+}", f.response_node, f.response_direction);
    let mapped = [key.clone(), f.response_node.to_string()]
        .into_iter()
        .find_map(|k| Some(map.apply(&k)).filter(|m| *m != k));
    if let Some(mapped) = mapped {
        let (name, unit) = split_unit(&mapped);
        let channel = Channel::parse(name)
            .ok_or_else(|| format!("node {key} is mapped to '{mapped}', not a channel"))?;
        let unit = match unit {
            Some(u) => Some(
                Unit::parse(u)
                    .ok_or_else(|| format!("unknown unit '{u}' in the map of node {key}"))?,
            ),
            None => None,
        };
        return Ok((channel, unit));
    }
    let quantity = quantity_of(f.ordinate_type).ok_or_else(|| {
        format!(
            "node {key}: ordinate specific data type {} is not displacement (8), velocity (11), \
             acceleration (12) or force (13); name its channel with --columns {{\"{}\": \"acc<i>\"}}",
            f.ordinate_type, f.response_node
        )
    })?;
    let name = match quantity {
        Quantity::Acceleration => format!("acc{}", f.response_node),
        Quantity::Velocity => format!("vel{}", f.response_node),
        Quantity::Displacement => format!("disp{}", f.response_node),
        _ => "force".to_owned(),
    };
    Channel::parse(&name)
        .map(|c| (c, None))
        .ok_or_else(|| format!("node {key} is not a floor (1, 2, …): map it with --columns"))
}

fn direction_sign(direction: i64) -> f64 {
    if direction < 0 {
        -1.0
    } else {
        1.0
    }
}

/// A measured FRF from a universal file's FRFs (function type 4), all on one frequency grid.
pub fn read_frf(path: &Path, map: &ColumnMap) -> Result<MeasuredFrf, DataError> {
    let functions = read_functions(path)?;
    let err = |line: u64, message: String| DataError {
        path: path.to_owned(),
        line: Some(line),
        message,
    };
    let frfs: Vec<&Function> = functions.iter().filter(|f| f.function_type == 4).collect();
    let first = *frfs.first().ok_or_else(|| DataError {
        path: path.to_owned(),
        line: None,
        message: format!(
            "no FRF (dataset 58 of function type 4); the file's functions are of types {:?}",
            functions
                .iter()
                .map(|f| f.function_type)
                .collect::<Vec<_>>()
        ),
    })?;
    let frequency = first.abscissa.clone();
    if first.abscissa_type != 0 && first.abscissa_type != 18 {
        return Err(err(
            first.line,
            format!(
                "abscissa specific data type {}: an FRF's is frequency (18)",
                first.abscissa_type
            ),
        ));
    }
    check_frequency(&frequency)
        .map_err(|(k, m)| err(first.line, format!("point {}: {m}", k + 1)))?;
    let mut channels: Vec<FrfChannel> = Vec::new();
    for f in &frfs {
        if f.abscissa.len() != frequency.len()
            || f.abscissa
                .iter()
                .zip(&frequency)
                .any(|(a, b)| (a - b).abs() > 1e-9 * b.abs().max(1.0))
        {
            return Err(err(
                f.line,
                "its frequencies differ from the first FRF's: one grid for all channels".into(),
            ));
        }
        if f.reference_node != first.reference_node
            || f.reference_direction != first.reference_direction
        {
            return Err(err(f.line, format!(
                "reference {}:{:+} differs from the first FRF's {}:{:+}: one excitation per file",
                f.reference_node, f.reference_direction, first.reference_node, first.reference_direction
            )));
        }
        let (channel, unit) = channel_of(f, map).map_err(|m| err(f.line, m))?;
        if !matches!(channel, Channel::Response { .. }) {
            return Err(err(
                f.line,
                format!("'{}' is not a response channel", channel.name()),
            ));
        }
        let numerator = match unit {
            Some(u) => u.to_si(),
            None => {
                unit_factor(&f.ordinate_units, channel.quantity()).map_err(|m| err(f.line, m))?
            }
        };
        let excitation = match quantity_of(f.denominator_type) {
            Some(q @ (Quantity::Force | Quantity::Acceleration)) => q,
            _ => Quantity::Force,
        };
        let denominator =
            unit_factor(&f.denominator_units, excitation).map_err(|m| err(f.line, m))?;
        let sign = direction_sign(f.response_direction) * direction_sign(f.reference_direction);
        let factor = sign * numerator / denominator;
        if channels.iter().any(|c| c.channel == channel) {
            return Err(err(f.line, format!("a second FRF of '{}'", channel.name())));
        }
        let values = if f.complex {
            FrfValues::Complex(f.values.iter().map(|v| v * factor).collect())
        } else {
            return Err(err(
                f.line,
                "a real FRF: only complex FRFs (ordinate data type 5 or 6) are read".into(),
            ));
        };
        channels.push(FrfChannel { channel, values });
    }
    Ok(MeasuredFrf {
        path: path.to_owned(),
        frequency,
        channels,
    })
}

/// A time record from a universal file's time responses (function type 1): every record on one
/// time grid; the excitation a force record (or a channel the map names `force`/`ground_acc`).
pub fn read_record(path: &Path, map: &ColumnMap) -> Result<Measurement, DataError> {
    let functions = read_functions(path)?;
    let err = |line: u64, message: String| DataError {
        path: path.to_owned(),
        line: Some(line),
        message,
    };
    let series: Vec<&Function> = functions.iter().filter(|f| f.function_type == 1).collect();
    let first = *series.first().ok_or_else(|| DataError {
        path: path.to_owned(),
        line: None,
        message: "no time response (dataset 58 of function type 1)".into(),
    })?;
    let time = first.abscissa.clone();
    let mut named: Vec<(String, Vec<f64>)> = vec![("time".to_owned(), time.clone())];
    for f in &series {
        if f.complex {
            return Err(err(
                f.line,
                "a complex time response: time records are real".into(),
            ));
        }
        if f.abscissa.len() != time.len()
            || f.abscissa
                .iter()
                .zip(&time)
                .any(|(a, b)| (a - b).abs() > 1e-9 * b.abs().max(1.0))
        {
            return Err(err(
                f.line,
                "its times differ from the first record's: one grid for all channels".into(),
            ));
        }
        let (channel, unit) = channel_of(f, map).map_err(|m| err(f.line, m))?;
        let factor = match unit {
            Some(u) => u.to_si(),
            None => {
                unit_factor(&f.ordinate_units, channel.quantity()).map_err(|m| err(f.line, m))?
            }
        };
        let sign = direction_sign(f.response_direction);
        if named.iter().any(|(n, _)| *n == channel.name()) {
            return Err(err(
                f.line,
                format!("a second record of '{}'", channel.name()),
            ));
        }
        named.push((
            channel.name(),
            f.values.iter().map(|v| sign * factor * v.re).collect(),
        ));
    }
    Measurement::from_named_columns(path, named, &ColumnMap::default())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// One ASCII dataset 58 in the fixed columns of the format, double precision, even abscissa.
    #[allow(clippy::too_many_arguments)]
    fn dataset(
        function_type: i64,
        node: i64,
        direction: i64,
        (abscissa, ordinate, units): (i64, i64, &str),
        start: f64,
        step: f64,
        values: &[Complex<f64>],
        complex: bool,
    ) -> String {
        let mut s = format!("{:>6}\n{:>6}{:74}\n", -1, 58, "");
        for i in 1..=5 {
            s.push_str(&format!("{:<80}\n", format!("id{i}")));
        }
        s.push_str(&format!(
            "{:>5}{:>10}{:>5}{:>10} {:>10}{:>10}{:>4} {:>10}{:>10}{:>4}\n",
            function_type, 1, 0, 0, "rig", node, direction, "rig", 1, 1
        ));
        s.push_str(&format!(
            "{:>10}{:>10}{:>10}{:>13.5e}{:>13.5e}{:>13.5e}\n",
            if complex { 6 } else { 4 },
            values.len(),
            1,
            start,
            step,
            0.0
        ));
        for (kind, label) in [(abscissa, "Hz"), (ordinate, units), (13, "N"), (0, "NONE")] {
            s.push_str(&format!(
                "{kind:>10}{:>5}{:>5}{:>5} {:<20} {:<20}\n",
                0, 0, 0, "axis", label
            ));
        }
        let numbers: Vec<f64> = values
            .iter()
            .flat_map(|v| {
                if complex {
                    vec![v.re, v.im]
                } else {
                    vec![v.re]
                }
            })
            .collect();
        for chunk in numbers.chunks(4) {
            for x in chunk {
                s.push_str(&format!("{x:>20.11e}"));
            }
            s.push('\n');
        }
        s.push_str(&format!("{:>6}\n", -1));
        s
    }

    fn file(text: &str) -> tempfile::NamedTempFile {
        let mut f = tempfile::Builder::new()
            .suffix(".uff")
            .tempfile()
            .expect("temp");
        f.write_all(text.as_bytes()).expect("write");
        f
    }

    #[test]
    fn reads_ascii_frfs_with_units_and_directions() {
        let h: Vec<Complex<f64>> = (0..5)
            .map(|k| Complex::new(k as f64, -0.5 * k as f64))
            .collect();
        let text = dataset(4, 1, 1, (18, 12, "g"), 1.0, 0.5, &h, true)
            + &dataset(4, 2, -1, (18, 12, "m/s^2"), 1.0, 0.5, &h, true);
        let f = file(&text);
        let m = MeasuredFrf::read(f.path(), &ColumnMap::default()).expect("reads");
        assert_eq!(m.channel_names(), ["acc1", "acc2"]);
        assert_eq!(m.frequency, vec![1.0, 1.5, 2.0, 2.5, 3.0]);
        let FrfValues::Complex(a1) = &m.channels[0].values else {
            panic!("complex")
        };
        let FrfValues::Complex(a2) = &m.channels[1].values else {
            panic!("complex")
        };
        assert_eq!(a1[2], Complex::new(2.0, -1.0) * 9.80665);
        // A negative response direction flips the sign.
        assert_eq!(a2[2], Complex::new(-2.0, 1.0));
    }

    #[test]
    fn reads_a_time_record_with_its_force() {
        let force: Vec<Complex<f64>> = (0..4).map(|k| Complex::new(k as f64, 0.0)).collect();
        let acc: Vec<Complex<f64>> = (0..4).map(|k| Complex::new(0.1 * k as f64, 0.0)).collect();
        let text = dataset(1, 1, 1, (17, 13, "N"), 0.0, 0.25, &force, false)
            + &dataset(1, 3, 1, (17, 12, "NONE"), 0.0, 0.25, &acc, false);
        let f = file(&text);
        let m = Measurement::read(f.path()).expect("reads");
        assert_eq!(m.channel_names(), ["force", "acc3"]);
        assert_eq!(m.dt, 0.25);
        assert_eq!(m.excitation.values, vec![0.0, 1.0, 2.0, 3.0]);
    }

    #[test]
    fn refuses_bad_files_naming_file_and_line() {
        let h: Vec<Complex<f64>> = (0..5).map(|k| Complex::new(k as f64, 1.0)).collect();
        let good = dataset(4, 1, 1, (18, 12, "g"), 1.0, 0.5, &h, true);
        let cases: Vec<(String, u64, &str)> = vec![
            (
                good.replacen("   6         5", "   7         5", 1),
                9,
                "ordinate data type 7",
            ),
            (
                good.replacen("2.00000000000e0", "2.0000000000xe0", 1),
                15,
                "not a finite number",
            ),
            (
                good.replacen("g                   ", "furlong             ", 1),
                2,
                "units label 'furlong'",
            ),
            (
                good.lines().take(15).collect::<Vec<_>>().join("\n"),
                15,
                "the file ends after",
            ),
            (
                "    -1\n    58\n".to_owned(),
                2,
                "the file ends before ID line 1",
            ),
            ("hello\n".to_owned(), 1, "expected '-1'"),
        ];
        for (text, line, needle) in cases {
            let f = file(&text);
            let e = MeasuredFrf::read(f.path(), &ColumnMap::default()).expect_err(needle);
            let shown = e.to_string();
            assert!(shown.contains(needle), "{needle}: {shown}");
            assert!(shown.contains(&f.path().display().to_string()), "{shown}");
            assert_eq!(e.line, Some(line), "{shown}");
        }
    }
}
