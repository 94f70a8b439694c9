//! `docs/protocol.md`'s parameter table is written from `protocol::PARAMS` and the default
//! set: this test fails when they differ, and rewrites the table with
//! `GMS_WRITE_DOCS=1 cargo test -p gms-core --test all -- protocol_doc::`.

use gms_core::device::default_settings;
use gms_core::numtext::Num;
use gms_core::protocol::{Access, PARAMS, write_value};

const BEGIN: &str = "<!-- params:begin -->";
const END: &str = "<!-- params:end -->";

/// The table as markdown, one row per parameter.
fn table() -> String {
    let d = default_settings();
    let mut t = String::from("| path | unit | range | default |\n|---|---|---|---|\n");
    for p in PARAMS {
        let mut value = String::new();
        let range = match p.access {
            Access::Number { min, max, .. } => {
                write_value(p, &d, &mut value).unwrap();
                format!("{} … {}", Num(min), Num(max))
            }
            Access::Mode => {
                write_value(p, &d, &mut value).unwrap();
                "`none`, `static`, `gms`, `gms-adaptive`".to_string()
            }
            Access::Estimate(_) => {
                value = "(read-only estimate)".into();
                "—".to_string()
            }
        };
        t += &format!("| `{}` | {} | {} | {} |\n", p.path, p.unit, range, value);
    }
    t
}

#[test]
fn the_protocol_reference_lists_every_parameter() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/protocol.md");
    let doc = std::fs::read_to_string(path).unwrap();
    let (a, b) = (doc.find(BEGIN).unwrap(), doc.find(END).unwrap());
    let want = format!("{BEGIN}\n{}{END}", table());
    let have = &doc[a..b + END.len()];
    if have != want {
        if std::env::var_os("GMS_WRITE_DOCS").is_some() {
            std::fs::write(path, doc.replace(have, &want)).unwrap();
            return;
        }
        panic!(
            "docs/protocol.md's parameter table differs from protocol::PARAMS: rewrite it with \
             GMS_WRITE_DOCS=1 cargo test -p gms-core --test all -- protocol_doc::"
        );
    }
    // Every path appears once.
    for p in PARAMS {
        assert_eq!(
            have.matches(&format!("`{}`", p.path)).count(),
            1,
            "{}",
            p.path
        );
    }
}

/// The parameters of a group (the path's first segment: `pos`, `ff`, `map`, …) are listed
/// together: the window draws a group per run of them, and a group split in two would be two
/// widgets of one name.
#[test]
fn each_group_of_parameters_is_listed_together() {
    let mut seen: Vec<&str> = Vec::new();
    for p in PARAMS {
        let g = p.path.split('.').next().unwrap();
        if seen.last() != Some(&g) {
            assert!(!seen.contains(&g), "the group {g} comes back at {}", p.path);
            seen.push(g);
        }
    }
}
