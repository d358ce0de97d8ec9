use std::path::Path;

use nalgebra::DMatrix;
use serde_json::json;

use crate::cli::{CliError, design_error};

use crate::cli::validate::indent;
use crate::design::Assignment;
use crate::methods::detection_filter::study::Study;

pub fn exec(deck: &Path, as_json: bool) -> Result<(), CliError> {
    let study = Study::load(deck)?;
    let ranks = study
        .design_plant
        .structural_ranks()
        .ok_or_else(|| CliError::Internal("SVD of the controllability/observability matrix failed".into()))?;
    let p = &study.design_plant;
    let mut filters = Vec::with_capacity(study.detectors.len());
    for d in &study.detectors {
        let f = d.params.design(&study.design_plant, study.dt_s).map_err(|e| design_error(deck, &d.name, e))?;
        filters.push(f);
    }

    if as_json {
        let rows =
            |m: &DMatrix<f64>| (0..m.nrows()).map(|i| m.row(i).iter().copied().collect::<Vec<_>>()).collect::<Vec<_>>();
        let assignment = |a: &Assignment| {
            json!({
                "K": rows(&a.K),
                "closed_loop_eigenvalues": a.closed_loop_eigenvalues,
                "eigenvector_condition": a.eigenvector_condition,
                "relative_residual": a.relative_residual,
            })
        };
        let detectors: Vec<_> = study
            .detectors
            .iter()
            .zip(&filters)
            .map(|(d, f)| {
                json!({
                    "name": d.name,
                    "eigenvalues_per_s": d.params.eigenvalues_per_s,
                    "fault_directions": rows(&d.params.fault_directions.transpose()),
                    "continuous": assignment(&f.continuous),
                    "discrete": assignment(&f.discrete),
                    "bias_signatures": rows(&f.signatures.transpose()),
                })
            })
            .collect();
        let doc = json!({
            "deck": deck.display().to_string(),
            "study": study.name,
            "dt_s": study.dt_s,
            "states": p.state_names,
            "outputs": p.output_names,
            "ranks": ranks,
            "detectors": detectors,
        });
        println!("{}", serde_json::to_string_pretty(&doc).map_err(|e| CliError::Internal(e.to_string()))?);
        return Ok(());
    }

    println!("{}: {}", deck.display(), study.name);
    println!(
        "rank ctrb(A, B) = {} of {}, rank obsv(A, C) = {} of {}",
        ranks.controllability_rank, ranks.states, ranks.observability_rank, ranks.states
    );
    for (d, filter) in study.detectors.iter().zip(&filters) {
        println!(
            "\ndetector {:?}: detection filter, eigenvalues [{}] 1/s",
            d.name,
            d.params.eigenvalues_per_s.iter().map(|l| format!("{l}")).collect::<Vec<_>>().join(", ")
        );
        let discrete_label = format!("discrete time, dt = {} s", study.dt_s);
        for (label, a) in [("continuous time", &filter.continuous), (discrete_label.as_str(), &filter.discrete)] {
            println!(
                "{label}: K (rows: states {}; columns: outputs {})",
                p.state_names.join(", "),
                p.output_names.join(", ")
            );
            print!("{}", indent(&format!("{:.6}", a.K)));
            let evs: Vec<String> = a
                .closed_loop_eigenvalues
                .iter()
                .map(|e| if e.im == 0.0 { format!("{:.9}", e.re) } else { format!("{:.9}{:+.9}i", e.re, e.im) })
                .collect();
            println!("  eigenvalues of A - K C: [{}]", evs.join(", "));
            println!("  eigenvector condition number: {:.6}", a.eigenvector_condition);
            println!("  assignment residual |(A - K C) F - F Lambda| / |A F|: {:.3e}", a.relative_residual);
        }
        println!("steady residual per unit bias on each output (columns: faulty output; rows: residual)");
        print!("{}", indent(&format!("{:.4}", filter.signatures)));
    }
    Ok(())
}
