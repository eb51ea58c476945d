//! Integer-step time.

/// `steps` communication steps of `step` seconds from `start`; `time(k) = start + k·step`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Clock {
    pub start: f64,
    pub step: f64,
    pub steps: u64,
}

impl Clock {
    pub fn new(start: f64, step: f64, steps: u64) -> Self {
        Clock { start, step, steps }
    }

    /// The time of communication point `k`: one multiplication, never a running sum, so the
    /// rounding error does not grow with `k`.
    #[inline]
    pub fn time(&self, k: u64) -> f64 {
        self.start + k as f64 * self.step
    }

    pub fn stop(&self) -> f64 {
        self.time(self.steps)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_land_exactly_on_the_stop_time() {
        let clock = Clock::new(0.0, 1.0 / 51.2, 1024);
        assert_eq!(clock.stop(), 20.0);
        // A running sum of a step that is not a power of two drifts; the clock does not.
        let tenth = Clock::new(0.0, 0.1, 1000);
        let summed = (0..1000).fold(0.0, |t, _| t + 0.1);
        assert_ne!(summed, 100.0);
        assert_eq!(tenth.stop(), 100.0);
    }
}
