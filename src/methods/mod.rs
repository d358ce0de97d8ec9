//! The study methods, one folder each, and the registry through which the command line finds them.

pub mod accelerometer;
pub mod air_data;
pub mod detection_filter;
pub mod surface_bank;
pub mod thrust_loss;

use crate::engine::method::Method;

/// Every kind of study fdimc runs: adding a method is its folder and one line here.
pub static REGISTRY: &[&dyn Method] = &[
    &detection_filter::DetectionFilters,
    &thrust_loss::ThrustLoss,
    &air_data::AirDataMethod,
    &accelerometer::Accelerometers,
    &surface_bank::SurfaceBanks,
];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::method::method_of;

    /// Kinds and marker tables are unique, and every bundled deck is read by the method its name says.
    #[test]
    fn every_bundled_deck_finds_its_method() {
        for (i, m) in REGISTRY.iter().enumerate() {
            for o in &REGISTRY[..i] {
                assert!(m.kind() != o.kind() && m.marker() != o.marker(), "{} and {}", m.kind(), o.kind());
            }
        }
        let expected = [
            ("seed000", "detection_filter"),
            ("seed001", "thrust_loss"),
            ("seed002", "air_data"),
            ("seed003", "accelerometer"),
            ("seed004", "surface_bank"),
        ];
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("studies");
        let mut decks = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy().to_string();
            let text = std::fs::read_to_string(&path).unwrap();
            let method = method_of(REGISTRY, &text, &path).unwrap();
            let (_, kind) = expected.iter().find(|(seed, _)| name.contains(seed)).expect("deck named after its seed");
            assert_eq!(method.kind(), *kind, "{name}");
            method.load(&text, &path).unwrap();
            decks += 1;
        }
        assert_eq!(decks, 16);
    }
}
