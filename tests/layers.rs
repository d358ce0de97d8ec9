//! The layering rule of `docs/architecture.md`, checked on the imports of `src/`: no file imports one
//! that imports it back (directly or around a circle), and no layer imports a higher one.
//!
//! Imports are read as `python3 ../shared/tools/import_cycles.py` reads them: every `crate::` and
//! `super::` path in the code (comments and the test module skipped), resolved to the longest existing
//! module file.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The layers of the crate, lowest first: a module imports only modules of its own layer or lower
/// ones. A module is named by its path under `src/` without `.rs` (`engine/run` is the folder, `cli`
/// the folder, `linalg` the file); a file belongs to the longest name that is a prefix of its path.
const LAYERS: &[&[&str]] = &[
    // Blocks that know nothing of studies.
    &["linalg", "dual", "lti", "kinematics", "estimation", "design", "fmu", "exact"],
    // The engine, in the order data flows.
    &["engine/stats"],
    &["engine/scenario"],
    &["engine/run"],
    &["engine/results"],
    &["engine/rare_event", "engine/sensitivity", "engine/worst_case", "engine/logs"],
    &["engine/report"],
    &["engine/method", "engine"],
    // Blocks built on the engine's deck sections, and models more than one method flies.
    &["fault", "checks", "vehicles"],
    &["methods"],
    &["cli"],
    &["lib", "main"],
];

/// A module: its path under `src/` as parts (`["engine", "run", "runner"]`; `[]` for lib.rs).
type Module = Vec<String>;

/// Every `.rs` file under `src`, by module.
fn modules(src: &Path) -> BTreeMap<Module, PathBuf> {
    let mut out = BTreeMap::new();
    let mut stack = vec![src.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let rel = path.strip_prefix(src).unwrap().with_extension("");
                let mut parts: Module = rel.iter().map(|p| p.to_string_lossy().into_owned()).collect();
                if parts.last().is_some_and(|p| p == "mod") {
                    parts.pop();
                }
                if parts == ["lib"] || parts == ["main"] {
                    parts.clear();
                }
                out.insert(parts, path);
            }
        }
    }
    out
}

/// The code of a file without comments and without its test module (from `#[cfg(test)] mod` on).
fn code(text: &str) -> String {
    let cut = text
        .match_indices("#[cfg(test)]")
        .find(|(i, _)| {
            let rest = text[i + "#[cfg(test)]".len()..].trim_start();
            let rest = rest.strip_prefix("pub ").unwrap_or(rest);
            rest.starts_with("mod ")
        })
        .map_or(text.len(), |(i, _)| i);
    text[..cut].lines().filter(|l| !l.trim_start().starts_with("//")).collect::<Vec<_>>().join("\n")
}

/// The paths after `crate::` and `super::` in `code`: (`true` for `crate`, the names after it).
fn paths(code: &str) -> Vec<(bool, Vec<String>)> {
    let bytes = code.as_bytes();
    let word = |b: u8| b.is_ascii_alphanumeric() || b == b'_';
    let mut out = Vec::new();
    for head in ["crate::", "super::"] {
        for (i, _) in code.match_indices(head) {
            if i > 0 && word(bytes[i - 1]) {
                continue;
            }
            let mut names = Vec::new();
            let mut j = i + head.len();
            loop {
                let start = j;
                while j < bytes.len() && word(bytes[j]) {
                    j += 1;
                }
                if j == start {
                    break;
                }
                names.push(code[start..j].to_string());
                if code[j..].starts_with("::") {
                    j += 2;
                } else {
                    break;
                }
            }
            out.push((head == "crate::", names));
        }
    }
    out
}

/// Module `from` imports these modules.
fn imports(files: &BTreeMap<Module, PathBuf>) -> BTreeMap<Module, BTreeSet<Module>> {
    let resolve = |parts: &[String]| -> Option<Module> {
        (1..=parts.len()).rev().map(|k| parts[..k].to_vec()).find(|m| files.contains_key(m))
    };
    let mut edges = BTreeMap::new();
    for (module, path) in files {
        let text = std::fs::read_to_string(path).unwrap();
        let mut to = BTreeSet::new();
        for (from_crate, names) in paths(&code(&text)) {
            // `super` of module a::b (file a/b.rs, or folder a/b/ by its mod.rs) is a.
            let mut full: Module =
                if from_crate { Vec::new() } else { module[..module.len().saturating_sub(1)].to_vec() };
            full.extend(names);
            if let Some(target) = resolve(&full).filter(|t| t != module && !t.is_empty()) {
                to.insert(target);
            }
        }
        edges.insert(module.clone(), to);
    }
    edges
}

/// The layer of a module: the index in [`LAYERS`] of the longest name that is a prefix of its path.
fn layer_of(module: &Module, layers: &[&[&str]]) -> Option<(usize, String)> {
    let path = if module.is_empty() { "lib".to_string() } else { module.join("/") };
    let mut best: Option<(usize, String)> = None;
    for (i, names) in layers.iter().enumerate() {
        for name in names.iter() {
            let is_prefix = path == *name || path.starts_with(&format!("{name}/"));
            if is_prefix && best.as_ref().is_none_or(|(_, b)| name.len() > b.len()) {
                best = Some((i, name.to_string()));
            }
        }
    }
    best
}

/// Every breach of the rule in the crate at `src`, as lines to print: circles of files, imports of a
/// higher layer, files in no layer.
fn breaches(src: &Path, layers: &[&[&str]]) -> Vec<String> {
    let files = modules(src);
    let edges = imports(&files);
    let show = |m: &Module| files[m].strip_prefix(src).unwrap().display().to_string();
    let mut out = Vec::new();
    for (from, tos) in &edges {
        let Some((lf, nf)) = layer_of(from, layers) else {
            out.push(format!("{} is in no layer: add it to LAYERS", show(from)));
            continue;
        };
        for to in tos {
            if let Some((lt, nt)) = layer_of(to, layers)
                && lt > lf
            {
                out.push(format!("{} ({nf}) imports {} ({nt}), a higher layer", show(from), show(to)));
            }
        }
    }
    // Circles: every file that reaches itself. A folder's mod.rs that only declares its children is
    // reached from them by `super::` paths; a circle of a mod.rs and its own children is not one.
    for start in edges.keys() {
        let mut seen = BTreeSet::new();
        let mut stack: Vec<(Module, Vec<Module>)> = vec![(start.clone(), vec![start.clone()])];
        while let Some((at, route)) = stack.pop() {
            for next in &edges[&at] {
                if next == start {
                    let parent_and_children =
                        route.len() == 2 && (route[1].starts_with(start) || start.starts_with(&route[1]));
                    if !parent_and_children && route.iter().min() == Some(start) {
                        let names: Vec<String> = route.iter().chain([start]).map(show).collect();
                        out.push(format!("circle: {}", names.join(" -> ")));
                    }
                } else if seen.insert(next.clone()) {
                    let mut r = route.clone();
                    r.push(next.clone());
                    stack.push((next.clone(), r));
                }
            }
        }
    }
    out
}

#[test]
fn src_keeps_its_layers_and_has_no_circles() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let found = breaches(&src, LAYERS);
    assert!(found.is_empty(), "the layering rule of docs/architecture.md is broken:\n{}", found.join("\n"));
    // The rule is read from real imports: the runner imports the deck's sections, a lower layer.
    let files = modules(&src);
    let edges = imports(&files);
    let runner: Module = ["engine", "run", "runner"].iter().map(|s| s.to_string()).collect();
    let deck: Module = ["engine", "scenario", "deck"].iter().map(|s| s.to_string()).collect();
    assert!(edges[&runner].contains(&deck), "{:?}", edges[&runner]);
    // The exact answers share nothing with what they check: they import no module outside their own.
    let exact: Vec<&Module> = edges.keys().filter(|m| m.first().is_some_and(|p| p == "exact")).collect();
    assert_eq!(exact.len(), 4, "{exact:?}");
    for m in exact {
        let outside: Vec<&Module> = edges[m].iter().filter(|t| t.first().is_none_or(|p| p != "exact")).collect();
        assert!(outside.is_empty(), "src/exact/{} imports {outside:?}", m.join("/"));
    }
}

/// A small crate with a planted upward import and a planted circle: both are found, named by file.
#[test]
fn a_planted_upward_import_and_a_circle_are_found() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path();
    let write = |path: &str, text: &str| {
        let p = src.join(path);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, text).unwrap();
    };
    write("lib.rs", "pub mod low;\npub mod high;\n");
    write("low/mod.rs", "pub mod a;\npub mod b;\n");
    // a -> b -> a: a circle inside one layer. b also reaches up into `high`.
    write(
        "low/a.rs",
        "use super::b::B;\npub struct A;\n#[cfg(test)]\nmod tests {\n    use crate::high::H; // test code may reach anywhere\n}\n",
    );
    write(
        "low/b.rs",
        "use crate::low::a::A;\n// use crate::high::H; (a comment is no import)\nfn f() -> crate::high::H { todo!() }\npub struct B;\n",
    );
    write("high.rs", "pub struct H;\n");
    let layers: &[&[&str]] = &[&["low"], &["high"], &["lib"]];
    let found = breaches(src, layers);
    assert_eq!(
        found,
        vec![
            "low/b.rs (low) imports high.rs (high), a higher layer".to_string(),
            "circle: low/a.rs -> low/b.rs -> low/a.rs".to_string(),
        ],
        "{found:#?}"
    );
    // Without the planted import and circle, the same crate passes.
    write("low/b.rs", "pub struct B;\n");
    assert_eq!(breaches(src, layers), Vec::<String>::new());
}
