//! Measurement records in and out, in one place: the CSV file (`time,force,acc1,acc2,acc3`: s,
//! N, m/s², uniformly sampled; extra columns kept by name and ignored unless asked for), the
//! same columns from arrays in memory, one CSV line at a time for a live stream, and the CSV
//! writer. A bad file is refused with its name, the line and the problem.

mod read;
pub mod stream;
pub(crate) mod write;

pub use read::{DataError, Measurement};
pub use stream::{nominal_step, LineLayout, DEFAULT_HEADER};
pub use write::{csv_text, format_g9};

/// The columns every record has.
pub const REQUIRED_COLUMNS: [&str; 5] = ["time", "force", "acc1", "acc2", "acc3"];
