//! The study methods, one folder each, and the registry through which the command line finds them.

pub mod accelerometer;
pub mod air_data;
mod bad_input;
pub mod detection_filter;
pub mod surface_bank;
pub mod thrust_loss;

use crate::engine::method::Method;

/// Every kind of study fdimc runs: adding a method is its folder and one line here.
pub static REGISTRY: &[&Method] = &[
    &detection_filter::METHOD,
    &thrust_loss::METHOD,
    &air_data::METHOD,
    &accelerometer::METHOD,
    &surface_bank::METHOD,
];

#[cfg(test)]
#[path = "../../tests/support/build_fmus.rs"]
mod build_fmus;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::method::method_of;

    /// Kinds and marker tables are unique, and every bundled deck is read by the method its name says.
    #[test]
    fn every_bundled_deck_finds_its_method() {
        // The command line's registry refuses a kind or marker taken twice (it panics).
        assert_eq!(crate::cli::registry_with(&[]).len(), REGISTRY.len());
        let expected = [
            ("seed000", "detection_filter"),
            ("b747", "detection_filter"), // a 24-state aircraft on method 000's kind (README)
            ("seed001", "thrust_loss"),
            ("seed002", "air_data"),
            ("seed003", "accelerometer"),
            ("replay_px4", "accelerometer"), // method 003 on a real log (README "Real flight logs")
            ("seed004", "surface_bank"),
            ("fmu_", "detection_filter"), // method 000 on an FMU truth (docs/fmu.md)
            ("starter_detection_filter", "detection_filter"), // `fdimc new detection_filter`
        ];
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        // The FMU decks fly the test FMUs, built from fmus/ as `cargo run --example build_fmus` does.
        super::build_fmus::build_all(root, &root.join("studies").join("fmus")).unwrap();
        let dir = root.join("studies");
        let mut decks = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_none_or(|e| e != "toml") {
                continue; // studies/logs/: the flight logs decks replay
            }
            let name = path.file_name().unwrap().to_string_lossy().to_string();
            let text = std::fs::read_to_string(&path).unwrap();
            let method = method_of(REGISTRY, &text, &path).unwrap();
            let (_, kind) = (expected.iter().find(|(seed, _)| name.contains(seed)))
                .unwrap_or_else(|| panic!("{name}: a deck is named after its seed (or listed here)"));
            assert_eq!(method.kind, *kind, "{name}");
            (method.load)(&text, &path).unwrap();
            decks += 1;
        }
        assert_eq!(decks, 44);
    }

    /// The shared `[monte_carlo]` fields are read by one piece of code: every kind says the same of the
    /// same mistake, and refuses, by name, a shared field it does not use.
    #[test]
    fn the_shared_monte_carlo_fields_get_the_same_messages_in_every_kind() {
        use crate::engine::method::Opt;
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("studies");
        for (k, m) in REGISTRY.iter().enumerate() {
            let path = dir.join(format!("ci_seed00{k}.toml"));
            let deck: toml::Table = toml::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
            assert!(deck.contains_key(m.marker), "{}", path.display());
            let broken = |key: &str, value: toml::Value| -> String {
                let mut d = deck.clone();
                d.get_mut("monte_carlo").and_then(|t| t.as_table_mut()).unwrap().insert(key.into(), value);
                let text = toml::to_string(&d).unwrap();
                match (m.load)(&text, std::path::Path::new("x.toml")) {
                    Ok(_) => "accepted".into(),
                    Err(e) => e.to_string(),
                }
            };
            let cases = [
                ("trials", toml::Value::Integer(0), "x.toml: monte_carlo.trials: allowed 1 to "),
                (
                    "noise_scale",
                    toml::Value::Float(-1.0),
                    "x.toml: monte_carlo.noise_scale: -1 is out of range; allowed >= 0",
                ),
                ("horizon", toml::Value::Integer(2), "x.toml: monte_carlo: unknown field `horizon`"),
            ];
            for (key, value, want) in cases {
                let got = broken(key, value);
                assert!(got.starts_with(want), "{}: {key}: {got}", m.kind);
            }
            let pfa = broken("target_pfa", toml::Value::Float(0.05));
            let confidence = broken("confidence", toml::Value::Float(0.95));
            if m.options.contains(&Opt::Thresholds) {
                assert_eq!((pfa.as_str(), confidence.as_str()), ("accepted", "accepted"), "{}", m.kind);
                let bad = broken("target_pfa", toml::Value::Float(1.5));
                assert!(bad.starts_with("x.toml: monte_carlo.target_pfa: allowed 0 < p < 1"), "{bad}");
                let bad = broken("confidence", toml::Value::Float(1.0));
                assert!(bad.starts_with("x.toml: monte_carlo.confidence: allowed 0 < c < 1"), "{bad}");
            } else {
                assert!(pfa.starts_with("x.toml: monte_carlo.target_pfa: not used by "), "{}: {pfa}", m.kind);
                assert!(confidence.starts_with("x.toml: monte_carlo.confidence: not used by "), "{}", m.kind);
            }
        }
    }
}
