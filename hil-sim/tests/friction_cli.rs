//! The `hil-sim friction` command as a user runs it: files in, files out, exit codes.

use std::path::{Path, PathBuf};
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_hil-sim");

use crate::common;

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

/// Runs `hil-sim friction`; returns (exit code, stderr).
fn friction(params: &Path, input: &Path, output: &Path) -> (i32, String) {
    let (code, _, err) = common::run(
        Command::new(BIN)
            .arg("friction")
            .arg("--params")
            .arg(params)
            .arg("--input")
            .arg(input)
            .arg("--output")
            .arg(output),
    );
    (code, err)
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Parses OUT.csv into (header, rows of f64).
fn read_out(p: &Path) -> (String, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(p).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().to_string();
    let rows = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    (header, rows)
}

const SLIDE: &str = "[friction]\nfs = 1.0\nfc = 0.6\nvs = 0.01\ndelta = 1\nsigma = 0.5\nc = 100\n\
                     blocks = [{ k = 1e4, alpha = 0.5 }, { k = 1e3, alpha = 0.5 }]\n";

#[test]
fn example_files_run_and_give_one_row_per_input_row() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.csv");
    let input = examples().join("trajectory.csv");
    for params in ["table1.toml", "guideway.toml"] {
        let (code, err) = friction(&examples().join(params), &input, &out);
        assert_eq!(code, 0, "{err}");
        let (header, rows) = read_out(&out);
        assert_eq!(header, "t,x,v,f");
        let n_in = std::fs::read_to_string(&input).unwrap().lines().count() - 1;
        assert_eq!(rows.len(), n_in);
        assert_eq!(&rows[0][2..], &[0.0, 0.0]);
        // v is the finite difference of the input.
        let v1 = (rows[1][1] - rows[0][1]) / (rows[1][0] - rows[0][0]);
        assert!((rows[1][2] - v1).abs() <= 1e-12 * v1.abs());
    }
    // Table 1: the torque never exceeds Fs + sigma |v| (220 uN·m + viscous).
    friction(&examples().join("table1.toml"), &input, &out);
    let (_, rows) = read_out(&out);
    for r in &rows {
        assert!(
            r[3].abs() <= 220e-6 * 1.0001 + 10.5e-6 * r[2].abs(),
            "{r:?}"
        );
    }
}

#[test]
fn constant_velocity_gives_the_stribeck_curve_for_every_model() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.csv");
    // One long row at each velocity (t, x columns in the other order, an extra column).
    let mut traj = String::from("x,note,t\n0,start,0\n");
    let (mut x, mut t) = (0.0f64, 0.0f64);
    let vels = [0.002, 0.01, 0.05, -0.02];
    for v in vels {
        t += 10.0;
        x += v * 10.0;
        traj += &format!("{x},v={v},{t}\n");
    }
    let input = write(dir.path(), "traj.csv", &traj);
    let s = |v: f64| v.signum() * (0.6 + 0.4 * (-(v.abs() / 0.01)).exp()) + 0.5 * v;
    let lugre = "[friction]\nmodel = \"lugre\"\nfs = 1.0\nfc = 0.6\nvs = 0.01\nsigma = 0.5\n\
                 sigma0 = 1e5\nsigma1 = 100\n";
    let stat = "[friction]\nmodel = \"static\"\nfs = 1.0\nfc = 0.6\nvs = 0.01\nsigma = 0.5\n";
    for text in [SLIDE, lugre, stat] {
        let params = write(dir.path(), "p.toml", text);
        let (code, err) = friction(&params, &input, &out);
        assert_eq!(code, 0, "{err}");
        let (_, rows) = read_out(&out);
        for (r, v) in rows[1..].iter().zip(vels) {
            assert!((r[2] - v).abs() < 1e-12);
            assert!(
                (r[3] - s(v)).abs() < 1e-5 * s(v).abs(),
                "{text}: v={v}: {} vs {}",
                r[3],
                s(v)
            );
        }
    }
}

#[test]
fn negative_table_overrides_for_negative_velocity_and_many_blocks_work() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out.csv");
    let input = write(dir.path(), "t.csv", "t,x\n0,0\n10,0.1\n20,-0.1\n");
    let p = write(
        dir.path(),
        "p.toml",
        &format!("{SLIDE}[friction.negative]\nfs = 2.0\nfc = 1.5\n"),
    );
    assert_eq!(friction(&p, &input, &out).0, 0);
    let (_, rows) = read_out(&out);
    let want_pos = 0.6 + 0.4 * (-1.0f64).exp() + 0.005;
    let want_neg = -(1.5 + 0.5 * (-2.0f64).exp()) - 0.01;
    assert!((rows[1][3] - want_pos).abs() < 1e-5, "{}", rows[1][3]);
    assert!((rows[2][3] - want_neg).abs() < 1e-5, "{}", rows[2][3]);
    // 16 and 32 blocks: the quasi-static virgin curve is still sum(min(k x, alpha Fs)).
    for n in [16usize, 32] {
        let blocks: Vec<String> = (0..n)
            .map(|i| {
                format!(
                    "{{ k = {}, alpha = {} }}",
                    1e3 * (i + 1) as f64,
                    1.0 / n as f64
                )
            })
            .collect();
        let text = format!(
            "[friction]\nfs = 1\nfc = 0.5\nvs = 1\nc = 10\nblocks = [{}]\n",
            blocks.join(", ")
        );
        let p = write(dir.path(), "n.toml", &text);
        let input = write(dir.path(), "q.csv", "t,x\n0,0\n1e9,2e-4\n");
        let (code, err) = friction(&p, &input, &out);
        assert_eq!(code, 0, "{err}");
        let (_, rows) = read_out(&out);
        let want: f64 = (0..n)
            .map(|i| (1e3 * (i + 1) as f64 * 2e-4).min(1.0 / n as f64))
            .sum();
        assert!(
            (rows[1][3] - want).abs() < 1e-5,
            "{n} blocks: {} vs {want}",
            rows[1][3]
        );
    }
}

/// Every kind of bad input: exit code 2, one line on stderr naming the file and the line or
/// key, and no OUT.csv (an existing one untouched).
#[test]
fn bad_input_exits_2_with_one_line_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let good_p = write(d, "good.toml", SLIDE);
    let good_t = write(d, "good.csv", "t,x\n0,0\n1,1e-3\n");
    let cases: Vec<(PathBuf, PathBuf, &[&str])> = vec![
        (
            d.join("missing.toml"),
            good_t.clone(),
            &["missing.toml", "cannot read"],
        ),
        (
            good_p.clone(),
            d.join("missing.csv"),
            &["missing.csv", "cannot read"],
        ),
        (
            write(d, "syntax.toml", "[friction]\nfs = = 1\n"),
            good_t.clone(),
            &["syntax.toml:2:"],
        ),
        (
            write(d, "unknown.toml", &format!("{SLIDE}sigma2 = 1\n")),
            good_t.clone(),
            &["unknown.toml:", "sigma2"],
        ),
        (
            write(d, "k.toml", &SLIDE.replace("k = 1e3", "k = -1e3")),
            good_t.clone(),
            &["k.toml", "blocks[1].k must be > 0"],
        ),
        (
            write(d, "fs.toml", &SLIDE.replace("fs = 1.0", "fs = 0.5")),
            good_t.clone(),
            &["fs.toml", "fs must be >= fc"],
        ),
        (
            write(
                d,
                "alpha.toml",
                &SLIDE.replace("alpha = 0.5 }]", "alpha = 0.9 }]"),
            ),
            good_t.clone(),
            &["alpha.toml", "alpha"],
        ),
        (
            write(d, "nofc.toml", &SLIDE.replace("fc = 0.6\n", "")),
            good_t.clone(),
            &["nofc.toml", "`fc`"],
        ),
        (
            write(d, "nan.toml", &SLIDE.replace("c = 100", "c = nan")),
            good_t.clone(),
            &["nan.toml", "c is not a finite number"],
        ),
        (
            write(d, "model.toml", &format!("{SLIDE}model = \"maxwell\"\n")),
            good_t.clone(),
            &["model.toml:"],
        ),
        (
            write(d, "nofriction.toml", "fs = 1\n"),
            good_t.clone(),
            &["nofriction.toml"],
        ),
        (
            good_p.clone(),
            write(d, "nocol.csv", "t,y\n0,0\n"),
            &["nocol.csv", "`x`"],
        ),
        (
            good_p.clone(),
            write(d, "short.csv", "t,x,z\n0,0,0\n1,2\n"),
            &["short.csv:3:", "fields"],
        ),
        (
            good_p.clone(),
            write(d, "nant.csv", "t,x\n0,0\nNaN,1\n"),
            &["nant.csv:3:", "`t`"],
        ),
        (
            good_p.clone(),
            write(d, "infx.csv", "t,x\n0,0\n1,inf\n"),
            &["infx.csv:3:", "`x`"],
        ),
        (
            good_p.clone(),
            write(d, "word.csv", "t,x\n0,0\n1,abc\n"),
            &["word.csv:3:", "`x`"],
        ),
        (
            good_p.clone(),
            write(d, "back.csv", "t,x\n0,0\n2,1\n1,2\n"),
            &["back.csv:4:", "does not increase"],
        ),
        (
            good_p.clone(),
            write(d, "same.csv", "t,x\n0,0\n0,1\n"),
            &["same.csv:3:", "does not increase"],
        ),
        (
            good_p.clone(),
            write(d, "empty.csv", ""),
            &["empty.csv", "`t`"],
        ),
        (
            good_p.clone(),
            write(d, "bin.csv", "t,x\n\u{0}\u{1}\u{ff},\u{7f}\n"),
            &["bin.csv:2:"],
        ),
    ];
    for (params, input, want) in cases {
        for existing in [false, true] {
            let out = d.join("out.csv");
            let _ = std::fs::remove_file(&out);
            if existing {
                std::fs::write(&out, "old contents\n").unwrap();
            }
            let (code, err) = friction(&params, &input, &out);
            assert_eq!(code, 2, "{params:?} {input:?}: {err}");
            assert_eq!(err.trim_end().lines().count(), 1, "not one line: {err}");
            for w in want {
                assert!(err.contains(w), "{err:?} should contain {w:?}");
            }
            if existing {
                assert_eq!(std::fs::read_to_string(&out).unwrap(), "old contents\n");
            } else {
                assert!(!out.exists(), "{params:?} {input:?} left an OUT.csv");
            }
            // No temporary files left behind either.
            let stray: Vec<_> = std::fs::read_dir(d)
                .unwrap()
                .filter_map(|e| e.ok())
                .filter(|e| e.file_name().to_string_lossy().starts_with(".tmp"))
                .collect();
            assert!(stray.is_empty(), "temporary files left: {stray:?}");
        }
    }
    // An output in a directory that does not exist: exit 2, one line.
    let (code, err) = friction(&good_p, &good_t, &d.join("no/such/dir/out.csv"));
    assert_eq!(code, 2);
    assert!(err.contains("cannot write"), "{err}");
}
