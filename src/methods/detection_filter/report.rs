//! Method 000's own part of `fdimc report`: each `--trials` trial's residuals, one panel per output,
//! with the deck's and the calibrated thresholds, the onset and the first alarm (the engine's generic
//! trace has no thresholds to draw).

use std::path::Path;

use plotters::prelude::*;

use crate::engine::report::plots::{FONT, color, e, legend};
use crate::engine::report::{ReportContext, ReportPart};
use crate::engine::results::thresholds::read_thresholds;
use crate::engine::run::output::Trace;
use crate::engine::run::runner::RunError;
use crate::engine::scenario::deck::FromDeck;
use crate::methods::detection_filter::scenario::TrialSpec;
use crate::methods::detection_filter::study::LtiStudy;
use crate::methods::detection_filter::trial::DetectorOutcome;
use crate::methods::detection_filter::trials::Engine;

/// The traces of `ctx.trials`, re-simulated from the run's deck (checked by its SHA-256).
pub fn report_part(ctx: &ReportContext) -> Result<ReportPart, RunError> {
    let mut part = ReportPart::default();
    // Without the run's deck there are no bounds; asked-for traces then refuse it by name below.
    let study = match ctx.run_deck() {
        Ok(deck) => Some(LtiStudy::load(&deck).map_err(|e| RunError::Invalid(e.to_string()))?),
        Err(_) => None,
    };
    if let Some(section) = study.as_ref().map(|s| analytic_section(ctx, s)).transpose()?.flatten() {
        part.sections.push(("False alarms without simulating".into(), section));
    }
    if ctx.trials.is_empty() {
        return Ok(part);
    }
    let m = ctx.manifest;
    let Some(mut study) = study else { return ctx.run_deck().map(|_| part) };
    study.header.seed = m.seed;
    study.monte_carlo.common.trials = m.trials;
    let engine = Engine::new(&study);
    let thresholds = read_thresholds(&ctx.dir.join("thresholds.csv"))?.detectors;
    let calibrated = thresholds.iter().find(|t| t.0 == study.detectors[0].name).map(|t| t.2.clone());
    for &trial in ctx.trials {
        if trial >= m.trials {
            return Err(RunError::Invalid(format!("--trials: trial {trial} is not in this run (0..{})", m.trials)));
        }
        let mut trace = Trace::default();
        let (spec, outcome) =
            engine.simulate(trial, 0, &mut trace).map_err(|e| RunError::Invalid(format!("trial {trial}: {e}")))?;
        let file = ctx.out.join(format!("trace_trial{trial}.svg"));
        draw(&file, &study, &spec, &outcome, &trace, calibrated.as_deref())
            .map_err(|e| RunError::Internal(format!("{}: {e}", file.display())))?;
        part.files.push(file);
    }
    Ok(part)
}

/// The analytic bounds ([`super::false_alarms`]) at the deck's and the calibrated thresholds beside what
/// the run saw there (`tail.csv`: the observed count and the tail fit), or why the deck has none.
fn analytic_section(ctx: &ReportContext, study: &LtiStudy) -> Result<Option<String>, RunError> {
    use crate::engine::report::html;
    use polars::prelude::df;
    let calibrated = read_thresholds(&ctx.dir.join("thresholds.csv")).map(|t| t.detectors).unwrap_or_default();
    // What the run saw at each set's thresholds: tail.csv's `pfa_at_thresholds` rows (none from a
    // summary written before it).
    let tail = crate::engine::results::tables::read_summary(&ctx.dir.join("tail.csv")).ok();
    let tail_row = |detector: &str, set: &str| -> Option<(f64, f64, f64, f64, f64)> {
        let t = crate::engine::results::tables::Table(tail.as_ref()?);
        let (d, th, q) = (t.strs("detector"), t.strs("thresholds"), t.strs("query"));
        let i = (0..d.len()).find(|&i| d[i] == detector && th[i] == set && q[i] == "pfa_at_thresholds")?;
        let v = |c: &str| t.f64s(c)[i];
        Some((v("observed_false_alarms"), v("trials"), v("pfa"), v("pfa_lo"), v("pfa_hi")))
    };
    let mut rows: Vec<[String; 7]> = Vec::new();
    let mut why = None;
    for d in &study.detectors {
        let filter = d
            .params
            .design(&study.design_plant, study.header.dt_s)
            .map_err(|e| RunError::Invalid(format!("detector {}: {e}", d.name)))?;
        let mut sets = vec![("deck", filter.thresholds.as_slice().to_vec())];
        if let Some(c) = calibrated.iter().find(|c| c.0 == d.name) {
            sets.push(("calibrated", c.2.clone()));
        }
        for (set, thresholds) in sets {
            match super::false_alarms::for_detector(study, &filter, &thresholds, super::false_alarms::CONDITIONAL_SEED)
            {
                Ok(a) => {
                    let seen = tail_row(&d.name, set);
                    rows.push([
                        d.name.clone(),
                        set.to_string(),
                        format!("[{:.3e}, {:.3e}]", a.lower, a.upper()),
                        a.lower_from(),
                        format!("{:.3e} [{:.3e}, {:.3e}]", a.conditional, a.conditional_lo, a.conditional_hi),
                        seen.map_or("-".into(), |s| format!("{:.0}/{:.0} = {:.3e}", s.0, s.1, s.0 / s.1)),
                        seen.map_or("-".into(), |s| format!("{:.3e} [{:.3e}, {:.3e}]", s.2, s.3, s.4)),
                    ]);
                }
                Err(w) => why = Some(w),
            }
        }
    }
    if rows.is_empty() {
        return Ok(why.map(|w| format!("<p>Not computed: {}.</p>", html::escape(&w))));
    }
    let col = |k: usize| rows.iter().map(|r| r[k].clone()).collect::<Vec<_>>();
    let df = df!(
        "detector" => col(0),
        "thresholds" => col(1),
        "pfa_per_trial_bounds" => col(2),
        "lower_bound_from" => col(3),
        "conditional_monte_carlo" => col(4),
        "observed" => col(5),
        "tail_fit (tail.csv)" => col(6),
    )
    .map_err(|e| RunError::Internal(e.to_string()))?;
    Ok(Some(format!(
        "<p>The fault-free residual of an exact model under white Gaussian noise is a Gaussian process whose law follows \
         from the closed loop; the probability of at least one alarm over a trial of {} samples lies between these \
         bounds, and conditional Monte Carlo on the same law gives it with a 95 % interval (<code>fdimc design</code> \
         prints both at the deck's thresholds). Beside them: what this run's trials saw, and the tail fit.</p>{}",
        study.header.steps,
        html::table(&df, &[])
    )))
}

/// Residuals of one trial, one panel per output: residual, +/- deck and calibrated thresholds,
/// onset and alarm times.
fn draw(
    file: &Path,
    study: &LtiStudy,
    spec: &TrialSpec,
    outcome: &DetectorOutcome,
    trace: &Trace,
    calibrated: Option<&[f64]>,
) -> Result<(), String> {
    let outputs = &study.plant.output_names;
    let t = &trace.float_columns.iter().find(|(n, _)| n == "t_s").ok_or("trace without t_s")?.1;
    let deck = &study.detectors[0].params.thresholds;
    let rows = outputs.len().div_ceil(2) as u32;
    let root = SVGBackend::new(file, (1100, 80 + 260 * rows)).into_drawing_area();
    root.fill(&WHITE).map_err(e)?;
    let fault = match spec.target_name(study) {
        Some(target) => format!("{target} {}", spec.fault.label()),
        None => "fault-free".into(),
    };
    let root = root
        .titled(&format!("Trial {}: {fault}; detector {}", spec.trial, study.detectors[0].name), (FONT, 20))
        .map_err(e)?;
    let panels = root.split_evenly((rows as usize, 2));
    for (j, name) in outputs.iter().enumerate() {
        let r = &trace.float_columns.iter().find(|(n, _)| *n == format!("r_{name}")).ok_or("trace without residual")?.1;
        let lim = r.iter().fold(deck[j], |m, v| m.max(v.abs())) * 1.15;
        let mut chart = ChartBuilder::on(&panels[j])
            .margin(8)
            .x_label_area_size(35)
            .y_label_area_size(65)
            .build_cartesian_2d(0f64..study.header.duration_s, -lim..lim)
            .map_err(e)?;
        chart.configure_mesh().x_desc("t (s)").y_desc(format!("r_{name}")).label_style((FONT, 12)).draw().map_err(e)?;
        chart
            .draw_series(LineSeries::new(t.iter().copied().zip(r.iter().copied()), color(0)))
            .map_err(e)?
            .label(format!("r_{name}"))
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], color(0)));
        for sign in [1.0, -1.0] {
            let s = chart
                .draw_series(LineSeries::new(
                    [(0.0, sign * deck[j]), (study.header.duration_s, sign * deck[j])],
                    color(1),
                ))
                .map_err(e)?;
            if sign > 0.0 {
                s.label("deck threshold").legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], color(1)));
            }
            if let Some(c) = calibrated.and_then(|c| c.get(j)) {
                let s = chart
                    .draw_series(LineSeries::new([(0.0, sign * c), (study.header.duration_s, sign * c)], color(2)))
                    .map_err(e)?;
                if sign > 0.0 {
                    s.label("calibrated threshold").legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], color(2)));
                }
            }
        }
        if spec.fault.onset_s.is_finite() {
            chart
                .draw_series(LineSeries::new(
                    [(spec.fault.onset_s, -lim), (spec.fault.onset_s, lim)],
                    BLACK.stroke_width(2),
                ))
                .map_err(e)?
                .label("onset")
                .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.stroke_width(2)));
        }
        if let Some((ta, _)) = outcome.detection.or(outcome.false_alarm) {
            chart
                .draw_series(LineSeries::new([(ta, -lim), (ta, lim)], color(3).stroke_width(2)))
                .map_err(e)?
                .label("first alarm")
                .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], color(3).stroke_width(2)));
        }
        legend(&mut chart, SeriesLabelPosition::UpperLeft, 11)?;
    }
    root.present().map_err(e)
}
