//! A force history alone: a `time,force` CSV (a header, then one sample a line at a constant
//! step), the excitation a hybrid test replays.

use std::path::Path;

use super::DataError;

/// The force and the step of a `time,force` CSV. Errors name the file and the line.
pub fn read_excitation(path: &Path) -> Result<(Vec<f64>, f64), DataError> {
    // The line in the message ("line 3: …"), as the hybrid test has always said it.
    let bad = |line: Option<u64>, message: String| DataError {
        path: path.to_owned(),
        line: None,
        message: match line {
            Some(l) => format!("line {l}: {message}"),
            None => message,
        },
    };
    let text = std::fs::read_to_string(path).map_err(|e| bad(None, e.to_string()))?;
    let mut lines = text.lines().enumerate();
    let header = lines.next().map(|(_, l)| l.trim()).unwrap_or("");
    let columns: Vec<&str> = header.split(',').map(str::trim).collect();
    if columns.len() < 2 || columns[0] != "time" || columns[1] != "force" {
        return Err(bad(
            Some(1),
            format!("the header must start with time,force, was '{header}'"),
        ));
    }
    let (mut time, mut force) = (Vec::new(), Vec::new());
    for (i, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let mut fields = line.split(',').map(str::trim);
        let mut number = |name: &str| -> Result<f64, DataError> {
            let field = fields.next().unwrap_or("");
            field
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    bad(
                        Some(i as u64 + 1),
                        format!("{name} '{field}' is not a finite number"),
                    )
                })
        };
        time.push(number("time")?);
        force.push(number("force")?);
    }
    if time.len() < 2 {
        return Err(bad(None, "fewer than two samples".into()));
    }
    let dt = (time[time.len() - 1] - time[0]) / (time.len() - 1) as f64;
    if !(dt > 0.0) {
        return Err(bad(None, "the time column does not increase".into()));
    }
    if let Some(k) = (1..time.len()).find(|&k| ((time[k] - time[k - 1]) - dt).abs() > 1e-6 * dt) {
        return Err(bad(
            Some(k as u64 + 2),
            format!(
                "the step {} s differs from the mean step {dt} s: resample it first",
                time[k] - time[k - 1]
            ),
        ));
    }
    Ok((force, dt))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The force and its step are read; a bad header, a bad number and an uneven step are
    /// refused naming the file and the line.
    #[test]
    fn a_force_history_is_read_and_its_faults_named_by_line() {
        let dir = tempfile::tempdir().expect("temp");
        let write = |name: &str, text: &str| {
            let p = dir.path().join(name);
            std::fs::write(&p, text).expect("write");
            p
        };
        let good = write("f.csv", "time,force\n0,1\n0.5,-2\n1.0,3\n");
        assert_eq!(
            read_excitation(&good).expect("reads"),
            (vec![1.0, -2.0, 3.0], 0.5)
        );
        let cases = [
            (
                "h.csv",
                "t,force\n0,1\n1,2\n",
                "line 1: the header must start with time,force",
            ),
            (
                "n.csv",
                "time,force\n0,1\n1,x\n",
                "line 3: force 'x' is not a finite number",
            ),
            (
                "s.csv",
                "time,force\n0,1\n1,2\n3,4\n",
                "line 3: the step 1 s differs",
            ),
        ];
        for (name, text, needle) in cases {
            let e = read_excitation(&write(name, text))
                .expect_err(name)
                .to_string();
            assert!(e.contains(name) && e.contains(needle), "{e}");
        }
    }
}
