//! The one error of modal identification: bad input, named.

/// What is wrong with the input of an identification (spectra, SSI-COV, LSCF, selection).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IdentificationError {
    #[error("{what}: no channels given")]
    NoChannels { what: &'static str },
    #[error("{what} has {got} samples; {expected} expected (as many as {reference})")]
    Length {
        what: String,
        got: usize,
        expected: usize,
        reference: String,
    },
    #[error("the sampling interval dt = {0} s is not a positive finite number")]
    SamplingInterval(f64),
    #[error("{what} = {value}: {rule}")]
    Option {
        what: &'static str,
        value: f64,
        rule: String,
    },
    #[error("{what} has {samples} samples; {needed} are needed ({why})")]
    TooShort {
        what: String,
        samples: usize,
        needed: usize,
        why: String,
    },
    #[error("{what} holds a non-finite value at sample {index}")]
    NonFinite { what: String, index: usize },
    #[error("{what}: {why}")]
    Numerical { what: &'static str, why: String },
}

pub(crate) fn check_dt(dt: f64) -> Result<(), IdentificationError> {
    if dt.is_finite() && dt > 0.0 {
        Ok(())
    } else {
        Err(IdentificationError::SamplingInterval(dt))
    }
}

/// Every channel finite, all of one length; that length.
pub(crate) fn check_channels(
    what: &'static str,
    channels: &[&[f64]],
) -> Result<usize, IdentificationError> {
    let first = channels
        .first()
        .ok_or(IdentificationError::NoChannels { what })?;
    let n = first.len();
    for (c, channel) in channels.iter().enumerate() {
        if channel.len() != n {
            return Err(IdentificationError::Length {
                what: format!("{what}, channel {}", c + 1),
                got: channel.len(),
                expected: n,
                reference: format!("{what}, channel 1"),
            });
        }
        if let Some(index) = channel.iter().position(|v| !v.is_finite()) {
            return Err(IdentificationError::NonFinite {
                what: format!("{what}, channel {}", c + 1),
                index,
            });
        }
    }
    Ok(n)
}
