//! Checks of a scenario generator's numbers that name the offending parameter: the generators' own
//! validation, beneath the decks' (which name the file and the TOML field).

use crate::fault::ChannelFault;

/// A number or a sensor fault a generator cannot take.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ValueError {
    #[error("{field} must be finite, got {value}")]
    NotFinite { field: &'static str, value: f64 },
    #[error("{field} must be positive, got {value}")]
    NotPositive { field: &'static str, value: f64 },
    #[error("{field} must not be negative, got {value}")]
    Negative { field: &'static str, value: f64 },
    #[error("fault {index} is on channel {channel}; {channels}")]
    FaultChannel { index: usize, channel: usize, channels: &'static str },
    #[error("fault {index}: onset {onset_s} s is not finite")]
    FaultOnset { index: usize, onset_s: f64 },
}

pub fn finite(field: &'static str, value: f64) -> Result<(), ValueError> {
    if value.is_finite() { Ok(()) } else { Err(ValueError::NotFinite { field, value }) }
}

pub fn positive(field: &'static str, value: f64) -> Result<(), ValueError> {
    finite(field, value)?;
    if value > 0.0 { Ok(()) } else { Err(ValueError::NotPositive { field, value }) }
}

pub fn non_negative(field: &'static str, value: f64) -> Result<(), ValueError> {
    finite(field, value)?;
    if value >= 0.0 { Ok(()) } else { Err(ValueError::Negative { field, value }) }
}

/// Every fault on one of `channels` sensors (described by `names`, e.g. "accelerometer channels are
/// 0 (x), 1 (y), 2 (z)"), with a finite onset.
pub fn sensor_faults(faults: &[ChannelFault], channels: usize, names: &'static str) -> Result<(), ValueError> {
    for (index, f) in faults.iter().enumerate() {
        if f.channel >= channels {
            return Err(ValueError::FaultChannel { index, channel: f.channel, channels: names });
        }
        if !f.onset_s.is_finite() {
            return Err(ValueError::FaultOnset { index, onset_s: f.onset_s });
        }
    }
    Ok(())
}
