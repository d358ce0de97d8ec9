//! Calibration flights of method 001's design: the loss fit (the seed's eq. 27) from noise-free or
//! noisy flights flown with the online detector, and the peak of `fhat` over a flight.

use std::sync::Arc;

use super::design::*;
use super::detector::*;
use crate::engine::scenario::noise::NoiseRng;
use crate::engine::scenario::streams::{Substream, noise_rng};
use crate::methods::thrust_loss::vehicle::{ENGINES, LaunchVehicleConfig, SensorNoise, ThrustFault, Vehicle};

impl MheDesign {
    /// Calibrates the linear loss fit (the seed's eq. 27) from flights of `config` with a loss of each of
    /// `losses_percent` at `onset_s`, the peak of `|fhat|` taken over `horizon_s` after the onset;
    /// returns the fit and the `(loss %, peak |fhat|)` pairs. Noise-free (`noise: None`): one flight per
    /// loss on the reference engine. Noisy: `flights_per_loss` flights per loss with the deck's sensor
    /// noise, on engines 1, 2, 3, 4, 1, .. in turn, flight `j` of loss `i` drawing its noise from stream
    /// `first_stream + i * flights_per_loss + j` of `seed` (flown in parallel; the pairs keep that
    /// order, so the fit is the same for any thread count). A noisy peak is the noise-free one plus the
    /// largest noise excursion near it, so a noise-free fit reads noisy flights high; a noisy fit absorbs
    /// that. The fit holds for onsets near `onset_s` (`S` and so `fhat` grow by about 50 % from 20 s to
    /// 50 s as the inertia falls); `LossTable` (`trial.rs`) builds the seed's table over onset time from
    /// one fit per onset.
    pub fn calibrate_loss_fit(
        self: &Arc<Self>,
        config: &LaunchVehicleConfig,
        onset_s: f64,
        losses_percent: &[f64],
        horizon_s: f64,
        noise: Option<NoisyCalibration>,
    ) -> Result<(LossFit, Vec<(f64, f64)>), DesignError> {
        use rayon::prelude::*;
        let reference = self.params.mhe.reference_engine;
        let flights: Vec<(f64, usize, Option<u64>)> = match noise {
            None => losses_percent.iter().map(|&loss| (loss, reference, None)).collect(),
            Some(n) => (losses_percent.iter().enumerate())
                .flat_map(|(i, &loss)| {
                    (0..n.flights_per_loss).map(move |j| {
                        let stream = n.first_stream + (i * n.flights_per_loss + j) as u64;
                        (loss, (reference + j) % ENGINES, Some(stream))
                    })
                })
                .collect(),
        };
        let pairs = flights
            .par_iter()
            .map(|&(loss, engine, stream)| {
                let fault = ThrustFault { engine, loss_fraction: loss / 100.0, onset_s };
                let peak = match (stream, noise) {
                    (Some(stream), Some(n)) => {
                        let mut rng = noise_rng(n.seed, stream, Substream::SensorNoise);
                        self.peak_fhat_flown(config, Some(fault), onset_s, horizon_s, Some(&mut rng))?
                    }
                    _ => self.peak_fhat(config, Some(fault), onset_s, horizon_s)?,
                };
                Ok((loss, peak))
            })
            .collect::<Result<Vec<_>, DesignError>>()?;
        Ok((LossFit::fit(&pairs)?, pairs))
    }

    /// Largest `|fhat|` from `from_s` to `from_s + horizon_s` of a noise-free flight of `config` with
    /// `fault`.
    pub fn peak_fhat(
        self: &Arc<Self>,
        config: &LaunchVehicleConfig,
        fault: Option<ThrustFault>,
        from_s: f64,
        horizon_s: f64,
    ) -> Result<f64, DesignError> {
        self.peak_fhat_flown(config, fault, from_s, horizon_s, None::<&mut NoiseRng>)
    }

    /// [`MheDesign::peak_fhat`] with the sensor noise of `config` drawn from `rng` (noise-free when
    /// `None`).
    fn peak_fhat_flown<R: rand::Rng + ?Sized>(
        self: &Arc<Self>,
        config: &LaunchVehicleConfig,
        fault: Option<ThrustFault>,
        from_s: f64,
        horizon_s: f64,
        mut rng: Option<&mut R>,
    ) -> Result<f64, DesignError> {
        let mut flown = config.clone();
        if rng.is_none() {
            flown.noise = SensorNoise::none();
        }
        let mut vehicle = Vehicle::new(&flown, fault)?;
        let mut detector = EkfMhe::new(Arc::clone(self), None);
        let mut peak = 0.0f64;
        while vehicle.time_s() <= from_s + horizon_s + 1e-9 {
            let m = match rng.as_deref_mut() {
                Some(rng) => vehicle.step(rng)?,
                None => vehicle.step_exact()?,
            };
            let out = detector.step(&m);
            if m.t_s >= from_s - 1e-9 {
                peak = peak.max(out.fhat.abs());
            }
        }
        Ok(peak)
    }
}

/// Noisy flights for a loss fit ([`MheDesign::calibrate_loss_fit`]): how many per loss, and the seed
/// and first stream their sensor noise is drawn from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoisyCalibration {
    pub flights_per_loss: usize,
    pub seed: u64,
    pub first_stream: u64,
}
