//! The GP input vector: the current and `q` previous samples of the three physics accelerations
//! and the force (the reference paper's section 4.2), kept in a ring buffer that the FMU advances
//! at each communication step.
//!
//! Layout of `x` (length `4 (q + 1)`), channel by channel, oldest sample first:
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

/// Channels of one sample: physics accelerations of floors 1..3 and the force.
pub const CHANNELS: usize = 4;

/// One sample: `[ÿp1, ÿp2, ÿp3, F]` (m/s², m/s², m/s², N).
pub type Sample = [f64; CHANNELS];

/// Length of the input vector for `lags` lags: `4 (lags + 1)`.
pub fn input_dimension(lags: usize) -> usize {
    CHANNELS * (lags + 1)
}

/// The `lags` samples before the current one, newest first.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LagBuffer {
    lags: usize,
    previous: VecDeque<Sample>,
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
    pub fn push(&mut self, sample: Sample) {
        if self.lags == 0 {
            return;
        }
        if self.previous.len() == self.lags {
            self.previous.pop_back();
        }
        self.previous.push_front(sample);
    }

    /// The sample `lag` steps before `current` (`lag` = 0 is `current`), padded with the first
    /// sample seen when the buffer does not reach that far back.
    fn at(&self, lag: usize, current: &Sample) -> Sample {
        if lag == 0 {
            return *current;
        }
        self.previous
            .get(lag - 1)
            .or_else(|| self.previous.back())
            .copied()
            .unwrap_or(*current)
    }

    /// The GP input vector for the current sample (layout in the module documentation).
    pub fn input_vector(&self, current: &Sample) -> Vec<f64> {
        let mut x = Vec::with_capacity(input_dimension(self.lags));
        for channel in 0..CHANNELS {
            for lag in (0..=self.lags).rev() {
                x.push(self.at(lag, current)[channel]);
            }
        }
        x
    }
}

/// The input vectors of a whole record, one per sample, exactly as the FMU forms them when it is
/// stepped through the record from its first sample.
pub fn lagged_inputs(samples: &[Sample], lags: usize) -> Vec<Vec<f64>> {
    let mut buffer = LagBuffer::new(lags);
    samples
        .iter()
        .map(|sample| {
            let x = buffer.input_vector(sample);
            buffer.push(*sample);
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
