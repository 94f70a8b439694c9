//! gms-core's modules form layers, with no circle: each module's code uses only the modules of
//! its own layer and the layers below (the order in `src/lib.rs`). Read from the sources: a
//! `crate::m` in a line of code (not a comment) is a use of `m`.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// The layers, from the bottom; each holds the crate's top-level modules named.
const LAYERS: [&[&str]; 8] = [
    &["math", "numtext", "crc", "settings"],
    &["friction"],
    &["control"],
    &["drive"],
    &["protocol"],
    &["device"],
    &["boards"],
    &["selftest"],
];

fn layer_of(module: &str) -> Option<usize> {
    LAYERS.iter().position(|l| l.contains(&module))
}

fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            sources(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

#[test]
fn no_module_uses_a_layer_above_its_own() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&src, &mut files);
    let mut seen = BTreeSet::new();
    let mut wrong = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(&src).unwrap();
        let first = rel
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_str()
            .unwrap();
        let module = first.trim_end_matches(".rs");
        if module == "lib" {
            continue;
        }
        let own = layer_of(module).unwrap_or_else(|| panic!("{module}: in no layer"));
        seen.insert(module.to_string());
        let text = std::fs::read_to_string(f).unwrap();
        for (n, line) in text.lines().enumerate() {
            let code = line.split("//").next().unwrap_or("");
            for (at, _) in code.match_indices("crate::") {
                let used: String = code[at + 7..]
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                let Some(l) = layer_of(&used) else {
                    continue;
                };
                if l > own {
                    wrong.push(format!("{}:{}: {module} uses {used}", rel.display(), n + 1));
                }
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "uses of a layer above:\n{}",
        wrong.join("\n")
    );
    // Every layer's module exists: a renamed module is not silently unchecked.
    for m in LAYERS.iter().flat_map(|l| l.iter()) {
        assert!(seen.contains(*m), "{m}: no such module");
    }
}
