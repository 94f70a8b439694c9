//! `gms-tune frf` end to end against the virtual device: its files, the notch proposed and
//! applied, bad input refused.
//!
//! One test at a time (each starts a virtual device, most of them faster than real time);
//! the devices are this binary itself (`serve_child`, `hil_sim::harness`).

use crate::support;
use support::*;

/// `gms-tune frf --loop open --suggest --apply` on the virtual device (20× real time): a line
/// per point, frf.csv with its header, margins.toml with its four keys, bode.svg; the notch
/// proposed is set; the bridge is off after it.
#[test]
fn frf_writes_its_files_suggests_and_applies_a_notch() {
    let _one = support::one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The earlier default loop (both loops at 20 kHz, the current loop's bandwidth 1 kHz, kp
    // 0.7) with a derivative gain a fifth above its own: about 11° of phase margin at rest,
    // on the ideal bridge it was tuned on (the real one's dead time, uncompensated at rest
    // within its band, changes the small-signal loop).
    let sc = quiet_scenario(
        d,
        "[plant.bridge]\nideal = true\n[controller.rate]\ncur_hz = 20000.0\n[controller.cur]\nkp = 1.5\nki = 6e4\n\
         [controller.pos]\nkp = 0.7\nki = 600.0\nkd = 3.2e-4\nd_filter_hz = 8000.0\n",
    );
    let srv = Server::child("tcp", &d.join("flash.img"), 20.0, Some(&sc));
    let (code, out, err) = tune(
        &srv,
        &[
            "frf",
            "--loop",
            "open",
            "--points",
            "16",
            "--amplitude",
            "0.003",
            "--out",
            "f",
            "--suggest",
            "--apply",
        ],
        d,
    );
    assert_eq!(code, 0, "{out}\n{err}");
    assert!(err.contains("16 points from 10 to 5000 Hz"), "{err}");
    let csv = std::fs::read_to_string(d.join("f/frf.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("f_hz,gain_db,phase_deg,coherence"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    // The grid and the refinement where the margins are decided, in frequency order.
    assert!(rows.len() > 16, "{csv}");
    assert!(rows.windows(2).all(|w| w[0][0] < w[1][0]));
    assert!(rows.iter().all(|r| (0.0..=1.0).contains(&r[3])));
    let m: toml::Table = std::fs::read_to_string(d.join("f/margins.toml"))
        .unwrap()
        .parse()
        .unwrap();
    for k in [
        "gain_margin_db",
        "phase_margin_deg",
        "crossover_hz",
        "peak_sensitivity_db",
    ] {
        let v = m[k].as_float().unwrap();
        assert!(v.is_finite(), "{k} {v}");
    }
    // At rest the pre-sliding resonance leaves this loop little phase margin.
    assert!(m["phase_margin_deg"].as_float().unwrap() < 20.0);
    assert!(out.contains("warning: the margins"), "{out}");
    assert!(d.join("f/bode.svg").exists());
    assert!(
        out.contains("notch 1 at") && out.contains("set filt.notch1.f_hz"),
        "{out}"
    );
    let f: f64 = tune(&srv, &["get", "filt.notch1.f_hz"], d)
        .1
        .trim()
        .parse()
        .unwrap();
    assert!(f > 300.0 && f < 2000.0, "{f}");
    let (_, status, _) = tune(&srv, &["send", "status"], d);
    assert!(status.contains("enabled=0"), "{status}");
}

/// Bad input to `gms-tune frf` and to the device's `frf`: clear one-line errors, nothing
/// moved; an axis that does not respond (an open winding): exit 1, the bridge off, the points
/// measured kept.
#[test]
fn frf_refuses_bad_input() {
    let _one = support::one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = quiet_scenario(d, "");
    let srv = Server::child("tcp", &d.join("flash.img"), 20.0, Some(&sc));
    for (args, says) in [
        (
            &["frf", "--loop", "open", "--to", "9500"][..],
            "above the position loop's Nyquist limit",
        ),
        (
            &["frf", "--loop", "plant", "--amplitude", "5"][..],
            "beyond the current limit lim.i_max",
        ),
        (
            &["frf", "--loop", "plant", "--suggest"][..],
            "--suggest and --apply need --loop open",
        ),
        (
            &["frf", "--loop", "open", "--from", "0"][..],
            "need 0 < from < to",
        ),
    ] {
        let (code, out, err) = tune(&srv, args, d);
        assert_eq!(code, 2, "{args:?}: {out}\n{err}");
        assert!(err.contains(says), "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{err}");
    }
    // The protocol's own refusals.
    let (code, _, err) = tune(&srv, &["send", "frf current 100 0.003 8 2"], d);
    assert_eq!(code, 1);
    assert!(err.contains("disabled (enable first)"), "{err}");
    tune(&srv, &["send", "enable"], d);
    let (code, _, err) = tune(&srv, &["send", "frf current 9100 0.003 8 2"], d);
    assert_eq!(code, 1);
    assert!(err.contains("below 0.45"), "{err}");
    let (code, _, err) = tune(&srv, &["send", "frf current 100 5 8 2"], d);
    assert_eq!(code, 1);
    assert!(err.contains("beyond lim.i_max"), "{err}");
    let (code, _, err) = tune(&srv, &["send", "frf position 100 1 8 2"], d);
    assert_eq!(code, 1);
    assert!(err.contains("speed limit"), "{err}");
    tune(&srv, &["send", "disable"], d);
    drop(srv);
    // An open winding: no current flows, nothing responds.
    let sc = quiet_scenario(d, "resistance = 1e5\n[controller.motor]\nr = 10.0");
    let srv = Server::child("tcp", &d.join("flash2.img"), 20.0, Some(&sc));
    let (code, out, err) = tune(
        &srv,
        &["frf", "--loop", "plant", "--points", "6", "--out", "g"],
        d,
    );
    assert_eq!(code, 1, "{out}\n{err}");
    assert!(
        err.contains("the axis does not respond") && err.contains("the bridge is off"),
        "{err}"
    );
    let kept = std::fs::read_to_string(d.join("g/frf.csv")).unwrap();
    assert_eq!(kept.lines().count(), 7, "{kept}");
    let (_, status, _) = tune(&srv, &["send", "status"], d);
    assert!(status.contains("enabled=0"), "{status}");
}
