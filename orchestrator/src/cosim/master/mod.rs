//! The fixed-step master algorithm: FMUs (slaves) and zero-time blocks connected output → input,
//! measured signals replayed as inputs, observers recording chosen outputs.
//!
//! One communication point `t_k` at a time, as one sentence: *apply inputs → evaluate outputs in
//! zero time → record → step every slave to `t_{k+1}`*. Time is an integer step count `k` with
//! `t_k = start + k·h` computed afresh (never accumulated), so 1024 steps of 1/51.2 s end at
//! exactly 20 s.
//!
//! Gauss–Seidel (default): nodes are evaluated in their order, each seeing the outputs its
//! predecessors produced at this same point; the pass repeats until no output changes, which
//! resolves loops through outputs without direct feedthrough (e.g. displacement → LQR → control
//! force → acceleration). Jacobi: every node sees the outputs as they were when the point was
//! reached, one pass, no iteration.

mod clock;
mod decimated;
mod recorder;
mod slave;
mod system;

pub use clock::Clock;
pub use decimated::Decimated;
pub use recorder::Recorder;
pub use slave::{Block, NodeId, Observer, Port, Slave};
pub use system::{
    Algorithm, PortType, Recording, RunEnd, SavedNode, SavedState, System, TypedPort,
};

#[derive(Debug, thiserror::Error)]
pub enum MasterError {
    #[error(transparent)]
    Import(#[from] crate::cosim::import::ImportError),
    #[error("block '{block}': {message}")]
    Block { block: String, message: String },
    #[error("system: {0}")]
    Config(String),
    /// The message carries the inner error's text; it is deliberately not also a `source`, so
    /// an error chain does not print it twice.
    #[error("at t = {time} s: {inner}")]
    AtTime { time: f64, inner: Box<MasterError> },
}
