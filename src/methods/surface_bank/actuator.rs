//! Actuator (control-surface) faults of method 004 (`docs/findings-seed004.md`): "the commanded deflection
//! of surface i is disconnected and replaced by a wrong signal".
//!
//! A fault acts on one surface (index into [`crate::vehicles::aerosonde::SURFACE_NAMES`]) over the window
//! `onset_s <= t < end_s` (`end_s = None`: to the end of the trial), at one of two places of the chain
//! `autopilot command -> actuator (lag, limits) -> position -> effective deflection -> airframe`:
//!
//! | kind                   | replaces                   | inside the window                             |
//! |------------------------|----------------------------|-----------------------------------------------|
//! | stuck                  | the actuator command       | `position_rad` (the lag still applies)        |
//! | oscillation            | the actuator command       | square wave between `low_rad` and `high_rad`  |
//! | loss of effectiveness  | the effective deflection   | `effectiveness * position`                    |
//!
//! Square wave: with `tau = t - onset_s`, the command is `high_rad` while `frac(tau / period_s) < 0.5`
//! and `low_rad` otherwise, i.e. it starts at `high_rad` at the onset, drops to `low_rad` half a period
//! later, and so on. The seed gives no period for its "square wave between -15 and 15 deg" (and 2..6 deg);
//! [`DEFAULT_SQUARE_WAVE_PERIOD_S`] = 2 s is the value the seed deck (`studies/seed004_surfaces.toml`)
//! documents. `period_s` must be positive and finite (decks validate it; a non-positive or NaN period
//! gives `low_rad` throughout).
//!
//! Because stuck and oscillation replace the *command*, the surface travels to the wrong value through
//! the actuator's first-order lag and is limited to its deflection range like any command; a loss of
//! effectiveness leaves the surface moving as commanded (a position sensor would see nothing) and only
//! weakens what acts on the airframe (`effectiveness` in `[0, 1]`, 0 = a floating surface with no effect).
//!
//! At most one fault per surface at a time is expected; if several are active on one surface they apply
//! in list order (a later command replacement wins; effectiveness factors multiply).

use crate::vehicles::aerosonde::SURFACES;

/// Period (s) of a square-wave fault when a Monte Carlo deck does not give one: the seed's scenario
/// states none; 2 s is the value `studies/seed004_surfaces.toml` documents.
pub const DEFAULT_SQUARE_WAVE_PERIOD_S: f64 = 2.0;

/// What a faulty actuator does inside its fault window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ActuatorFaultKind {
    /// The surface is driven to and held at `position_rad` (the actuator lag still applies on the way there).
    Stuck { position_rad: f64 },
    /// Square-wave command between `low_rad` and `high_rad` with period `period_s`: `high_rad` for the first
    /// half of each period counted from the onset, `low_rad` for the second half (see the module docs).
    Oscillation { low_rad: f64, high_rad: f64, period_s: f64 },
    /// The surface moves as commanded but only `effectiveness` (0..1) of its deflection acts on the airframe.
    LossOfEffectiveness { effectiveness: f64 },
}

impl ActuatorFaultKind {
    /// The size as decks give it: the stuck position (deg), the square wave's amplitude (half its
    /// peak-to-peak, deg), the effectiveness (fraction).
    pub fn size(&self) -> f64 {
        match *self {
            ActuatorFaultKind::Stuck { position_rad } => position_rad.to_degrees(),
            ActuatorFaultKind::Oscillation { low_rad, high_rad, .. } => 0.5 * (high_rad - low_rad).to_degrees(),
            ActuatorFaultKind::LossOfEffectiveness { effectiveness } => effectiveness,
        }
    }

    /// The unit of [`ActuatorFaultKind::size`].
    pub fn size_unit(&self) -> &'static str {
        match self {
            ActuatorFaultKind::Stuck { .. } | ActuatorFaultKind::Oscillation { .. } => "deg",
            ActuatorFaultKind::LossOfEffectiveness { .. } => "effectiveness (fraction)",
        }
    }

    /// The deck name of the kind.
    pub fn name(&self) -> &'static str {
        match self {
            ActuatorFaultKind::Stuck { .. } => "stuck",
            ActuatorFaultKind::Oscillation { .. } => "oscillation",
            ActuatorFaultKind::LossOfEffectiveness { .. } => "loss_of_effectiveness",
        }
    }
}

/// One fault of one control surface over `[onset_s, end_s)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActuatorFault {
    /// Surface index, order [`crate::vehicles::aerosonde::SURFACE_NAMES`] (0..5).
    pub surface: usize,
    pub kind: ActuatorFaultKind,
    pub onset_s: f64,
    /// End of the window (exclusive); `None`: the fault lasts to the end of the trial.
    pub end_s: Option<f64>,
}

impl ActuatorFault {
    /// Whether the fault acts at `t_s`: `onset_s <= t_s < end_s`.
    pub fn active(&self, t_s: f64) -> bool {
        self.onset_s <= t_s && self.end_s.is_none_or(|end| t_s < end)
    }

    /// The actuator command of this fault's surface after the fault: stuck and oscillation replace
    /// `commanded_rad` inside the window; a loss of effectiveness, or any kind outside the window, leaves it.
    pub fn command(&self, t_s: f64, commanded_rad: f64) -> f64 {
        if !self.active(t_s) {
            return commanded_rad;
        }
        match self.kind {
            ActuatorFaultKind::Stuck { position_rad } => position_rad,
            ActuatorFaultKind::Oscillation { low_rad, high_rad, period_s } => {
                let phase = ((t_s - self.onset_s) / period_s).rem_euclid(1.0);
                if phase < 0.5 { high_rad } else { low_rad }
            }
            ActuatorFaultKind::LossOfEffectiveness { .. } => commanded_rad,
        }
    }

    /// The deflection of this fault's surface acting on the airframe, from the actuator position: a loss of
    /// effectiveness scales it inside the window; the other kinds, or any kind outside the window, pass it.
    pub fn effective(&self, t_s: f64, position_rad: f64) -> f64 {
        match self.kind {
            ActuatorFaultKind::LossOfEffectiveness { effectiveness } if self.active(t_s) => {
                effectiveness * position_rad
            }
            _ => position_rad,
        }
    }
}

/// The five actuator commands after every fault active at `t_s` (in list order; see
/// [`ActuatorFault::command`]). Panics if a fault's surface is not below 5 (validate decks first).
pub fn faulty_commands(faults: &[ActuatorFault], t_s: f64, commanded_rad: &[f64; SURFACES]) -> [f64; SURFACES] {
    let mut out = *commanded_rad;
    for f in faults {
        out[f.surface] = f.command(t_s, out[f.surface]);
    }
    out
}

/// The five deflections acting on the airframe from the actuator positions, after every fault active at
/// `t_s` (in list order; see [`ActuatorFault::effective`]). Panics if a fault's surface is not below 5.
pub fn effective_positions(faults: &[ActuatorFault], t_s: f64, positions_rad: &[f64; SURFACES]) -> [f64; SURFACES] {
    let mut out = *positions_rad;
    for f in faults {
        out[f.surface] = f.effective(t_s, out[f.surface]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fault(surface: usize, kind: ActuatorFaultKind, onset_s: f64, end_s: Option<f64>) -> ActuatorFault {
        ActuatorFault { surface, kind, onset_s, end_s }
    }

    const CMD: [f64; 5] = [0.01, -0.02, 0.03, -0.04, 0.05];

    #[test]
    fn square_wave_starts_high_and_halves_each_period() {
        let (low, high) = (-0.25, 0.25);
        let f =
            fault(1, ActuatorFaultKind::Oscillation { low_rad: low, high_rad: high, period_s: 2.0 }, 70.0, Some(100.0));
        let cases = [
            (69.999, 0.7),  // before the onset: the command
            (70.0, high),   // onset: high
            (70.5, high),   // + 0.25 period
            (70.999, high), // just before half a period
            (71.0, low),    // half a period: low
            (71.5, low),    // + 0.75 period
            (72.0, high),   // one period: high again
            (99.5, low),    // 14.75 periods
            (99.999, low),  // just before the end
            (100.0, 0.7),   // end (exclusive): the command again
        ];
        for (t, want) in cases {
            assert_eq!(f.command(t, 0.7), want, "t = {t}");
            assert_eq!(f.effective(t, 0.3), 0.3, "an oscillation never scales the effect");
        }
        assert_eq!(f.kind.name(), "oscillation");
    }

    #[test]
    fn stuck_replaces_the_command_only_inside_its_window() {
        let f = fault(0, ActuatorFaultKind::Stuck { position_rad: -0.2618 }, 10.0, Some(40.0));
        let got: Vec<f64> = [9.99, 10.0, 25.0, 39.99, 40.0, 50.0].iter().map(|&t| f.command(t, 0.05)).collect();
        assert_eq!(got, [0.05, -0.2618, -0.2618, -0.2618, 0.05, 0.05]);
        assert!(!f.active(9.99) && f.active(10.0) && f.active(39.99) && !f.active(40.0));
        assert_eq!(f.effective(20.0, 0.1), 0.1);
        let all = faulty_commands(&[f], 20.0, &CMD);
        assert_eq!(all, [-0.2618, -0.02, 0.03, -0.04, 0.05]);
        assert_eq!(faulty_commands(&[f], 40.0, &CMD), CMD);
        assert_eq!(effective_positions(&[f], 20.0, &CMD), CMD);
        // Without an end the fault lasts.
        let open = ActuatorFault { end_s: None, ..f };
        assert!(open.active(1e9) && !open.active(9.0));
    }

    #[test]
    fn loss_of_effectiveness_scales_only_the_effective_deflection() {
        let f = fault(3, ActuatorFaultKind::LossOfEffectiveness { effectiveness: 0.25 }, 5.0, Some(6.0));
        assert_eq!(f.command(5.5, -0.04), -0.04);
        assert_eq!(faulty_commands(&[f], 5.5, &CMD), CMD);
        assert_eq!(effective_positions(&[f], 5.5, &CMD), [0.01, -0.02, 0.03, -0.01, 0.05]);
        assert_eq!(effective_positions(&[f], 4.99, &CMD), CMD);
        assert_eq!(effective_positions(&[f], 6.0, &CMD), CMD);
    }

    #[test]
    fn several_faults_apply_in_list_order() {
        let faults = [
            fault(4, ActuatorFaultKind::Stuck { position_rad: 0.1 }, 0.0, None),
            fault(4, ActuatorFaultKind::Stuck { position_rad: -0.1 }, 1.0, None),
            fault(2, ActuatorFaultKind::LossOfEffectiveness { effectiveness: 0.5 }, 0.0, None),
            fault(2, ActuatorFaultKind::LossOfEffectiveness { effectiveness: 0.5 }, 1.0, None),
        ];
        assert_eq!(faulty_commands(&faults, 0.5, &CMD)[4], 0.1);
        assert_eq!(faulty_commands(&faults, 1.5, &CMD)[4], -0.1, "the later replacement wins");
        assert_eq!(effective_positions(&faults, 0.5, &CMD)[2], 0.015);
        assert_eq!(effective_positions(&faults, 1.5, &CMD)[2], 0.0075, "factors multiply");
    }
}
