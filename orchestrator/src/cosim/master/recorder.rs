//! An observer that keeps every recorded value in memory.

use super::{Observer, Port};

/// An observer that keeps every value in memory: one column per watched port.
pub struct Recorder {
    ports: Vec<Port>,
    pub names: Vec<String>,
    pub time: Vec<f64>,
    pub columns: Vec<Vec<f64>>,
}

impl Recorder {
    pub fn new(watched: Vec<(String, Port)>) -> Self {
        Self::with_capacity(watched, 0)
    }

    /// A recorder with room for `samples` samples per column (no reallocation while a run of
    /// known length records).
    pub fn with_capacity(watched: Vec<(String, Port)>, samples: usize) -> Self {
        let (names, ports): (Vec<String>, Vec<Port>) = watched.into_iter().unzip();
        let columns = vec![Vec::with_capacity(samples); ports.len()];
        Recorder {
            ports,
            names,
            time: Vec::with_capacity(samples),
            columns,
        }
    }

    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|i| self.columns[i].as_slice())
    }

    /// `time,<names…>` with full precision.
    pub fn write_csv(&self, writer: impl std::io::Write) -> Result<(), csv::Error> {
        let mut w = csv::Writer::from_writer(writer);
        let mut header = vec!["time".to_owned()];
        header.extend(self.names.iter().cloned());
        w.write_record(&header)?;
        for (k, t) in self.time.iter().enumerate() {
            let mut row = vec![format!("{t}")];
            row.extend(self.columns.iter().map(|c| format!("{:e}", c[k])));
            w.write_record(&row)?;
        }
        w.flush()?;
        Ok(())
    }
}

impl Observer for Recorder {
    fn will_record(&mut self, points: usize) {
        self.time.reserve(points);
        for column in &mut self.columns {
            column.reserve(points);
        }
    }
    fn record(&mut self, time: f64, values: &[f64]) {
        self.time.push(time);
        for (column, &v) in self.columns.iter_mut().zip(values) {
            column.push(v);
        }
    }
    fn ports(&self) -> &[Port] {
        &self.ports
    }
}
