//! The lag vector: the current and `q` previous samples of the physics predictions of the
//! measured channels and the excitation (the reference paper's section 4.2, there the three
//! physics accelerations and the force), kept in a ring buffer that the FMU advances at each
//! communication step. Each channel's GP takes the blocks of some of its columns
//! ([`crate::layout::Layout::columns_of`]); on the paper's rig, all of them.
//!
//! Layout of `x` (length `(M + 1)(q + 1)` for M measured channels; `4 (q + 1)` on the paper's
//! rig), column by column, oldest sample first:
//!
//! ```text
//! [ ÿp1(t−q) … ÿp1(t),  ÿp2(t−q) … ÿp2(t),  ÿp3(t−q) … ÿp3(t),  F(t−q) … F(t) ]
//! ```
//!
//! Before `q` samples have been seen, the missing lags are padded with the first sample seen (at
//! the very first point, with the current sample): the structure is taken to have been at that
//! state for all earlier times.
//!
//! [`lagged_inputs`] builds the same vectors from a whole record, with the same padding, so a
//! training set built off-line lines up with what the FMU computes on-line.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

/// Columns of one sample on the paper's rig: physics accelerations of floors 1..3 and the force.
pub const CHANNELS: usize = 4;

/// One sample of the paper's rig: `[ÿp1, ÿp2, ÿp3, F]` (m/s², m/s², m/s², N). Another layout's
/// sample is a slice of [`crate::layout::Layout::sample_width`] values, in the same order: the
/// physics prediction of each measured channel, then the excitation.
pub type Sample = [f64; CHANNELS];

/// Length of the paper rig's input vector for `lags` lags: `4 (lags + 1)`.
pub fn input_dimension(lags: usize) -> usize {
    CHANNELS * (lags + 1)
}

/// The `lags` samples before the current one, newest first.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LagBuffer {
    lags: usize,
    previous: VecDeque<Vec<f64>>,
}

impl LagBuffer {
    pub fn new(lags: usize) -> Self {
        LagBuffer {
            lags,
            previous: VecDeque::with_capacity(lags),
        }
    }

    pub fn lags(&self) -> usize {
        self.lags
    }

    /// How many previous samples are held (at most `lags`).
    pub fn len(&self) -> usize {
        self.previous.len()
    }

    pub fn is_empty(&self) -> bool {
        self.previous.is_empty()
    }

    /// The current sample becomes lag 1; the oldest falls out once `lags` are held.
    pub fn push(&mut self, sample: impl AsRef<[f64]>) {
        if self.lags == 0 {
            return;
        }
        let reused = if self.previous.len() == self.lags {
            self.previous.pop_back()
        } else {
            None
        };
        let mut slot = reused.unwrap_or_default();
        slot.clear();
        slot.extend_from_slice(sample.as_ref());
        self.previous.push_front(slot);
    }

    /// The sample `lag` steps before `current` (`lag` = 0 is `current`), padded with the first
    /// sample seen when the buffer does not reach that far back.
    fn at<'a>(&'a self, lag: usize, current: &'a [f64]) -> &'a [f64] {
        if lag == 0 {
            return current;
        }
        self.previous
            .get(lag - 1)
            .or_else(|| self.previous.back())
            .map_or(current, Vec::as_slice)
    }

    /// The lag vector for the current sample (layout in the module documentation).
    pub fn input_vector(&self, current: &[f64]) -> Vec<f64> {
        let mut x = Vec::with_capacity(current.len() * (self.lags + 1));
        for channel in 0..current.len() {
            for lag in (0..=self.lags).rev() {
                x.push(self.at(lag, current)[channel]);
            }
        }
        x
    }
}

/// The input vectors of a whole record, one per sample, exactly as the FMU forms them when it is
/// stepped through the record from its first sample.
pub fn lagged_inputs<S: AsRef<[f64]>>(samples: &[S], lags: usize) -> Vec<Vec<f64>> {
    let mut buffer = LagBuffer::new(lags);
    samples
        .iter()
        .map(|sample| {
            let x = buffer.input_vector(sample.as_ref());
            buffer.push(sample);
            x
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(k: usize) -> Sample {
        let k = k as f64;
        [k, 10.0 + k, 20.0 + k, 30.0 + k]
    }

    #[test]
    fn layout_is_channel_by_channel_oldest_first() {
        let mut buffer = LagBuffer::new(2);
        buffer.push(sample(0));
        buffer.push(sample(1));
        let x = buffer.input_vector(&sample(2));
        assert_eq!(
            x,
            vec![0.0, 1.0, 2.0, 10.0, 11.0, 12.0, 20.0, 21.0, 22.0, 30.0, 31.0, 32.0]
        );
        assert_eq!(x.len(), input_dimension(2));
    }

    #[test]
    fn missing_lags_are_padded_with_the_first_sample() {
        let mut buffer = LagBuffer::new(3);
        // At the first point every lag is the current sample.
        assert_eq!(buffer.input_vector(&sample(5))[..4], [5.0, 5.0, 5.0, 5.0]);
        buffer.push(sample(5));
        buffer.push(sample(6));
        // Lags 1 and 2 exist (6, 5); lag 3 is padded with the first sample (5).
        assert_eq!(buffer.input_vector(&sample(7))[..4], [5.0, 5.0, 6.0, 7.0]);
        buffer.push(sample(7));
        buffer.push(sample(8));
        // Full: the first sample has fallen out.
        assert_eq!(buffer.input_vector(&sample(9))[..4], [6.0, 7.0, 8.0, 9.0]);
        assert_eq!(buffer.len(), 3);
    }

    #[test]
    fn zero_lags_is_the_current_sample_alone() {
        let mut buffer = LagBuffer::new(0);
        buffer.push(sample(1));
        assert!(buffer.is_empty());
        assert_eq!(buffer.input_vector(&sample(2)), vec![2.0, 12.0, 22.0, 32.0]);
    }

    #[test]
    fn a_record_gives_the_vectors_the_buffer_gives_step_by_step() {
        let samples: Vec<Sample> = (0..12).map(sample).collect();
        let off_line = lagged_inputs(&samples, 4);
        let mut buffer = LagBuffer::new(4);
        for (k, s) in samples.iter().enumerate() {
            assert_eq!(off_line[k], buffer.input_vector(s));
            buffer.push(*s);
        }
    }
}
