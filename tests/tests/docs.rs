//! Every reference in the README and docs/ resolves inside the repository: relative links
//! name files that exist (and headings that exist, for `#anchors` into markdown), and nothing
//! in the tree points at the design notes outside it.

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// GitHub's anchor of a heading: lower case, spaces to '-', punctuation dropped.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter_map(|c| match c {
            ' ' => Some('-'),
            c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
            _ => None,
        })
        .collect()
}

fn anchors(md: &str) -> Vec<String> {
    md.lines()
        .filter(|l| l.starts_with('#'))
        .map(|l| slug(l.trim_start_matches('#')))
        .collect()
}

/// The `](target)` links of a markdown text.
fn links(md: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = md;
    while let Some(i) = rest.find("](") {
        rest = &rest[i + 2..];
        if let Some(j) = rest.find(')') {
            out.push(rest[..j].to_string());
            rest = &rest[j..];
        }
    }
    out
}

fn markdown_files() -> Vec<PathBuf> {
    let mut v = vec![root().join("README.md")];
    for e in std::fs::read_dir(root().join("docs")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "md") {
            v.push(p);
        }
    }
    v
}

#[test]
fn links_resolve_inside_the_repository() {
    let mut checked = 0;
    for file in markdown_files() {
        let text = std::fs::read_to_string(&file).unwrap();
        let dir = file.parent().unwrap();
        for link in links(&text) {
            if link.starts_with("http://") || link.starts_with("https://") {
                continue;
            }
            let (path, anchor) = match link.split_once('#') {
                Some((p, a)) => (p, Some(a)),
                None => (link.as_str(), None),
            };
            let target = if path.is_empty() {
                file.clone()
            } else {
                dir.join(path)
            };
            assert!(
                target.exists(),
                "{}: link to {link} names no file",
                file.display()
            );
            assert!(
                target
                    .canonicalize()
                    .unwrap()
                    .starts_with(root().canonicalize().unwrap()),
                "{}: link to {link} leaves the repository",
                file.display()
            );
            if let (Some(a), Some("md")) = (anchor, target.extension().and_then(|e| e.to_str())) {
                let heads = anchors(&std::fs::read_to_string(&target).unwrap());
                assert!(
                    heads.iter().any(|h| h == a),
                    "{}: no heading #{a} in {}",
                    file.display(),
                    target.display()
                );
            }
            checked += 1;
        }
    }
    assert!(checked > 10, "{checked} links");
}

#[test]
fn nothing_points_outside() {
    let out = std::process::Command::new("git")
        .args(["grep", "-n", "-I", "-e", "DESIGN §", "-e", "../shared"])
        .current_dir(root())
        .output()
        .unwrap();
    let hits: Vec<String> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter(|l| !l.starts_with("tests/tests/docs.rs") && !l.starts_with(".ci/run"))
        .map(String::from)
        .collect();
    assert!(
        hits.is_empty(),
        "references outside the repository: {hits:#?}"
    );
}
