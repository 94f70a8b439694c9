//! The window (`gms_tune::ui::App`, its real widgets driven by egui_kittest without a display)
//! end to end against the virtual device.
//!
//! One test at a time (each starts a virtual device, most of them faster than real time);
//! the devices are this binary itself (`serve_child`, `hil_sim::harness`).

use crate::support;
use support::*;

/// Against `hil-sim serve`: the window lists every parameter path with its unit; the
/// telemetry's values change over time; Enable and Disable switch the bridge; a set typed in
/// the window changes the device (read back with `get` once the window is closed); a refused
/// set shows the device's error beside the field and the field shows the device's value again.
#[test]
fn the_window_shows_the_device_and_sets_what_it_is_told() {
    let _one = support::one_at_a_time();
    use egui_kittest::kittest::Queryable;
    use gms_core::protocol::PARAMS;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let srv = Server::child("tcp", &d.join("flash.img"), 1.0, None);
    let mut h = window(&srv);
    assert!(step_until(&mut h, srv.wall(0.1, 5.0), |a| a.rows.len()
        >= PARAMS.len()
        && a.samples.len() > 100));
    for p in PARAMS {
        // The field (labelled by its path) and its unit beside it.
        let field = h.get_by_label(p.path);
        assert!(field.value().is_some(), "{}", p.path);
        assert!(
            h.query_all_by_label(p.unit).count() > 0,
            "{} {}",
            p.path,
            p.unit
        );
    }
    // Live values: the time and the received count go on.
    let (t0, n0) = (h.state().samples.back().unwrap().t, h.state().received);
    assert!(step_until(&mut h, srv.wall(0.5, 1.0), |a| a
        .samples
        .back()
        .unwrap()
        .t
        > t0 + 0.5));
    let n1 = h.state().received;
    assert!(n1 > n0 + 300, "{n0} -> {n1}");
    assert!(h.query_by_label_contains("samples received").is_some());
    // Enable, then Disable: the status says so, and the window shows it.
    h.get_by_label("Enable").click();
    assert!(step_until(&mut h, srv.wall(0.1, 1.5), |a| a.bridge_on()));
    h.step();
    assert!(h.query_by_label("bridge on").is_some());
    h.get_by_label("Disable").click();
    assert!(step_until(&mut h, srv.wall(0.1, 1.5), |a| !a.bridge_on()));
    h.step();
    assert!(h.query_by_label("bridge off").is_some());
    // A set the device takes.
    type_param(&mut h, "pos.kd", "2.2e-4");
    let row = |a: &gms_tune::ui::App, p: &str| a.rows.iter().find(|r| r.listed.path == p).cloned();
    assert!(step_until(&mut h, srv.wall(0.1, 1.5), |a| row(a, "pos.kd")
        .unwrap()
        .listed
        .value
        == "0.00022"));
    // A set it refuses (out of range): the error beside the field, the field back at the default 0.49.
    type_param(&mut h, "pos.kp", "5000");
    assert!(step_until(&mut h, srv.wall(0.1, 1.5), |a| row(a, "pos.kp")
        .unwrap()
        .error
        .is_some()));
    h.step();
    let r = row(h.state(), "pos.kp").unwrap();
    assert!(
        r.error.as_deref().unwrap().contains("err 6"),
        "{:?}",
        r.error
    );
    assert_eq!(r.edit, "0.49");
    // Beside the field, and in the log below.
    assert_eq!(h.query_all_by_label_contains("err 6").count(), 2);
    assert_eq!(h.get_by_label("pos.kp").value().as_deref(), Some("0.49"));
    // The window closed, the device read back by another client.
    drop(h);
    assert_eq!(tune(&srv, &["get", "pos.kd"], d).1.trim(), "0.00022");
    assert_eq!(tune(&srv, &["get", "pos.kp"], d).1.trim(), "0.49");
}

/// The device gone: the window says the link is lost (and keeps drawing).
#[test]
fn the_window_shows_a_lost_link() {
    let _one = support::one_at_a_time();
    use egui_kittest::kittest::Queryable;
    let dir = tempfile::tempdir().unwrap();
    let mut srv = Server::child("tcp", &dir.path().join("flash.img"), 1.0, None);
    let mut h = window(&srv);
    assert!(step_until(&mut h, srv.wall(0.0, 5.0), |a| a.link
        == gms_tune::ui::app::LinkState::Up));
    srv.kill();
    assert!(step_until(&mut h, srv.wall(0.0, 5.0), |a| matches!(
        a.link,
        gms_tune::ui::app::LinkState::Lost(_)
    )));
    h.step();
    // In the top bar, and in the log below.
    assert!(h.query_all_by_label_contains("link lost").count() >= 2);
    // The window goes on drawing frames while the worker retries.
    for _ in 0..10 {
        h.step();
    }
}

/// The window's Experiments page: tune-ff typed in and started with its button on a virtual
/// device 10 × real time; the sweep's points arrive as it runs; the device's gain stays until
/// "Apply the gain", then it is the chosen one (read back with `get` once the window is
/// closed).
#[test]
fn the_window_runs_tune_ff_and_applies_it() {
    let _one = support::one_at_a_time();
    use egui_kittest::kittest::Queryable;
    use gms_tune::ui::worker::Outcome;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = quiet_scenario(d, "");
    let srv = Server::child("tcp", &d.join("flash.img"), 10.0, Some(&sc));
    let mut h = window(&srv);
    assert!(step_until(&mut h, srv.wall(0.0, 5.0), |a| !a
        .rows
        .is_empty()));
    h.state_mut().tab = gms_tune::ui::app::Tab::Experiments;
    h.step();
    for (label, v) in [("steps", "5"), ("seconds", "2")] {
        replace_text(&mut h, label, v);
    }
    h.get_by_label("Tune ff").click();
    h.step();
    assert!(h.state().running.is_some());
    let done = step_job(&mut h, &srv, 10.0, |a| a.outcome.is_some());
    assert!(done, "{:?} {:?}", h.state().running, h.state().log);
    let (chosen, before, points) = match h.state().outcome.clone().unwrap() {
        Ok(Outcome::TunedFf(t)) => (t.chosen, t.before, t.curve.len()),
        other => panic!("{other:?}"),
    };
    // 5 coarse tests, then 9 gains twice around the optimum.
    assert_eq!(points, 23);
    assert_eq!(h.state().ff_points.len(), 23);
    assert!((0.5..=1.3).contains(&chosen), "{chosen}");
    assert_eq!(before, 0.94);
    h.step();
    h.get_by_label("Apply the gain").click();
    assert!(step_until(&mut h, srv.wall(0.1, 1.5), |a| {
        a.rows
            .iter()
            .any(|r| r.listed.path == "ff.gain" && r.listed.value != "0.94")
    }));
    drop(h);
    let got: f64 = tune(&srv, &["get", "ff.gain"], d).1.trim().parse().unwrap();
    assert!((got - chosen).abs() < 1e-5, "{got} vs {chosen}");
}

/// Stop during a run from the window (an identification at real time): the run ends with
/// the window saying it stopped, the bridge is off and the stroke limits are back.
#[test]
fn the_window_stops_a_run_with_the_bridge_off() {
    let _one = support::one_at_a_time();
    use egui_kittest::kittest::Queryable;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = quiet_scenario(d, "");
    let srv = Server::child("tcp", &d.join("flash.img"), 1.0, Some(&sc));
    let mut h = window(&srv);
    assert!(step_until(&mut h, srv.wall(0.0, 5.0), |a| !a
        .rows
        .is_empty()));
    h.state_mut().tab = gms_tune::ui::app::Tab::Experiments;
    h.step();
    h.get_by_label("Identify").click();
    h.step();
    // Into the run (its first stage).
    assert!(step_job(&mut h, &srv, 5.0, |a| a
        .running
        .as_ref()
        .is_some_and(|r| r.done > 0.2)));
    h.get_by_label("Stop").click();
    assert!(step_job(&mut h, &srv, 5.0, |a| a.outcome.is_some()));
    let out = h.state().outcome.clone().unwrap();
    assert!(matches!(&out, Err(e) if e.contains("stopped")), "{out:?}");
    assert!(step_until(&mut h, srv.wall(0.1, 1.5), |a| !a.bridge_on()));
    drop(h);
    assert_eq!(tune(&srv, &["get", "lim.pos_max"], d).1.trim(), "50");
    assert_eq!(tune(&srv, &["get", "lim.pos_min"], d).1.trim(), "-50");
}

/// Export visible writes the samples of the plots' time window; Dump writes the device's
/// parameters as a parameter file; the step test moves the axis by the step and gives its
/// figures.
#[test]
fn the_window_exports_dumps_and_steps() {
    let _one = support::one_at_a_time();
    use egui_kittest::kittest::Queryable;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let srv = Server::child("tcp", &d.join("flash.img"), 1.0, None);
    let mut h = window_on(&srv, vec!["set pos.kd 2.2e-4".into(), "enable".into()]);
    assert!(step_until(&mut h, srv.wall(2.0, 5.0), |a| a.samples.len()
        > 2000
        && a.bridge_on()));
    h.state_mut().csv = d.join("live.csv").display().to_string();
    h.state_mut().file = d.join("dump.toml").display().to_string();
    h.step();
    h.get_by_label("Pause").click();
    h.step();
    h.get_by_label("Export visible").click();
    h.step();
    let text = std::fs::read_to_string(d.join("live.csv")).unwrap();
    let (a, b) = h.state().visible;
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(
        text.lines().next(),
        Some("t,pos,ref,error,ff,current,friction")
    );
    assert!(rows.len() > 1000, "{}", rows.len());
    assert!(rows.iter().all(|r| r.len() == 7 && r[0] >= a && r[0] <= b));
    h.get_by_label("Resume").click();
    h.get_by_label("Dump").click();
    assert!(step_until(&mut h, srv.wall(0.1, 1.5), |_| d
        .join("dump.toml")
        .exists()));
    let pf = gms_ident::paramfile::ParamFile::load(&d.join("dump.toml")).unwrap();
    assert_eq!(pf.device.unwrap()["pos.kd"].as_float(), Some(0.00022));
    // A step of 2e-4 rad (53 counts) on the Motion page.
    h.state_mut().tab = gms_tune::ui::app::Tab::Motion;
    h.step();
    h.get_by_label("Step").click();
    assert!(step_until(&mut h, srv.wall(2.0, 5.0), |a| a.step.is_some()));
    let s = h.state().step.clone().unwrap();
    let m = s.metrics;
    eprintln!(
        "step {} rad: settle {:.1} ms, steady-state {:.2} counts, largest {:.1} counts, \
         unsettled {}",
        s.step,
        m.settle_time * 1e3,
        m.steady_state_error / 3.8e-6,
        m.max_error / 3.8e-6,
        m.unsettled_steps
    );
    assert_eq!(s.step, 2e-4);
    // Where the reference went (53 counts) the axis followed: a steady-state error of noise
    // size; the largest error (tracking the move) well below the step.
    assert!(m.steady_state_error < 2.0 * 3.8e-6, "{m:?}");
    assert!(m.max_error < 0.5 * 2e-4, "{m:?}");
    h.step();
    assert!(h.query_by_label_contains("steady-state").is_some());
}

/// The window's Frequency response page: a sweep of the open loop measured, its points as
/// they come, the margins and the notch proposed.
#[test]
fn the_window_measures_a_frequency_response() {
    let _one = support::one_at_a_time();
    use egui_kittest::kittest::Queryable;
    use gms_tune::ui::worker::Outcome;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = quiet_scenario(d, "");
    let srv = Server::child("tcp", &d.join("flash.img"), 20.0, Some(&sc));
    let mut h = window(&srv);
    assert!(step_until(&mut h, srv.wall(0.0, 5.0), |a| !a
        .rows
        .is_empty()));
    h.state_mut().tab = gms_tune::ui::app::Tab::Frf;
    h.step();
    for (label, v) in [("points", "12"), ("amplitude", "0.003")] {
        replace_text(&mut h, label, v);
    }
    h.get_by_label("Measure").click();
    h.step();
    assert!(h.state().running.is_some());
    let done = step_job(&mut h, &srv, 10.0, |a| a.outcome.is_some());
    assert!(done, "{:?} {:?}", h.state().running, h.state().log);
    match h.state().outcome.clone().unwrap() {
        Ok(Outcome::Frf {
            sweep, suggestion, ..
        }) => {
            assert!(sweep.points.len() >= 12);
            assert_eq!(h.state().frf_points.len(), sweep.points.len());
            let m = sweep.margins.unwrap();
            assert!(m.phase_margin_deg.is_finite() && m.crossover_hz > 0.0);
            assert!(matches!(suggestion, Some(Ok(_))), "{suggestion:?}");
        }
        other => panic!("{other:?}"),
    }
    h.step();
    assert!(h.query_by_label("Apply the notch").is_some());
}

/// The window's Position map page on an axis with a hidden cogging: the map measured, its
/// ripple shown, applied (the device's map switched on, the switch showing it), switched off.
#[test]
fn the_window_measures_and_applies_a_position_map() {
    let _one = support::one_at_a_time();
    use egui_kittest::kittest::Queryable;
    use gms_tune::ui::worker::Outcome;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = quiet_scenario(
        d,
        "gear_ratio = 1.0\nlead = 1.13636e-4\n[plant.ripple]\namplitude = 20e-6\nper_rev = 12",
    );
    let srv = Server::child("tcp", &d.join("flash.img"), 20.0, Some(&sc));
    let mut h = window(&srv);
    assert!(step_until(&mut h, srv.wall(0.0, 5.0), |a| !a
        .rows
        .is_empty()));
    h.state_mut().tab = gms_tune::ui::app::Tab::Map;
    h.step();
    replace_text(&mut h, "bins", "256");
    h.get_by_label("Measure the map").click();
    h.step();
    assert!(h.state().running.is_some());
    let done = step_job(&mut h, &srv, 10.0, |a| a.outcome.is_some());
    assert!(done, "{:?} {:?}", h.state().running, h.state().log);
    match h.state().outcome.clone().unwrap() {
        Ok(Outcome::Map { map, .. }) => {
            assert_eq!(map.angle.len(), 256);
            let peak = map.offset.iter().fold(0.0f64, |a, o| a.max(o.abs()));
            assert!((peak - 20e-6).abs() < 4e-6, "{peak}");
        }
        other => panic!("{other:?}"),
    }
    h.step();
    h.get_by_label("Apply the map").click();
    let on = |a: &gms_tune::ui::App| {
        a.rows
            .iter()
            .any(|r| r.listed.path == "map.enable" && r.listed.value == "1")
    };
    assert!(
        step_until(&mut h, srv.wall(0.5, 5.0), on),
        "{:?}",
        h.state().log
    );
    h.get_by_label("the map acts (map.enable)").click();
    assert!(step_until(&mut h, srv.wall(0.1, 1.5), |a| !on(a)));
    drop(h);
    let bins: f64 = tune(&srv, &["get", "map.bins"], d)
        .1
        .trim()
        .parse()
        .unwrap();
    assert_eq!(bins, 256.0);
}

/// The window's Learning page: the iterations arrive one by one as the learning runs (each
/// shown before the run ends), the error over the period after it; Apply leaves the best
/// correction playing (the device's table says so).
#[test]
fn the_window_shows_the_learning_and_applies_it() {
    let _one = support::one_at_a_time();
    use egui_kittest::kittest::Queryable;
    use gms_tune::ui::worker::Outcome;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let srv = Server::child("tcp", &d.join("flash.img"), 20.0, None);
    let mut h = window(&srv);
    assert!(step_until(&mut h, srv.wall(0.0, 5.0), |a| !a
        .rows
        .is_empty()));
    h.state_mut().tab = gms_tune::ui::app::Tab::Learn;
    h.step();
    replace_text(&mut h, "iterations", "3");
    h.get_by_label("Learn").click();
    h.step();
    assert!(h.state().running.is_some());
    // Iterations come while the run goes on.
    let some = step_job(&mut h, &srv, 5.0, |a| !a.learn_points.is_empty());
    assert!(some && h.state().running.is_some(), "{:?}", h.state().log);
    let done = step_job(&mut h, &srv, 10.0, |a| a.outcome.is_some());
    assert!(done, "{:?} {:?}", h.state().running, h.state().log);
    let n = match h.state().outcome.clone().unwrap() {
        Ok(Outcome::Learned(l)) => {
            assert_eq!(l.iterations.len(), 4);
            assert_eq!(h.state().learn_points, l.iterations);
            l.correction.len()
        }
        other => panic!("{other:?}"),
    };
    assert_eq!(n, 1000);
    h.step();
    // The iterations' legend: "RMS" and "peak" once each (the lines and their points share
    // an entry).
    assert_eq!(h.query_all_by_label("RMS").count(), 1);
    assert_eq!(h.query_all_by_label("peak").count(), 1);
    h.get_by_label("Apply the correction").click();
    let applied = step_until(&mut h, srv.wall(0.5, 5.0), |a| {
        a.log.iter().any(|l| l.contains("the correction plays"))
    });
    assert!(applied, "{:?}", h.state().log);
    drop(h);
    let t = tune(&srv, &["send", "table"], d).1;
    assert!(!t.contains(" gen=0 "), "{t}");
}

/// On a device that runs at a tenth of real time (a loaded host, the image on emulated
/// silicon), the window's long jobs — the position map, a frequency response, the learning —
/// each show their progress in device time, and Stop ends each within the wall time such a
/// device needs for a few of its requests: the window says it stopped, the bridge is off.
#[test]
fn the_window_stops_its_jobs_on_a_device_at_a_tenth_of_real_time() {
    let _one = support::one_at_a_time();
    use egui_kittest::kittest::Queryable;
    use gms_tune::ui::app::Tab;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = quiet_scenario(d, "");
    let srv = Server::child("tcp", &d.join("flash.img"), 0.1, Some(&sc));
    let mut h = window(&srv);
    assert!(step_until(&mut h, srv.wall(0.0, 5.0), |a| !a
        .rows
        .is_empty()));
    for (tab, button) in [
        (Tab::Frf, "Measure"),
        (Tab::Map, "Measure the map"),
        (Tab::Learn, "Learn"),
    ] {
        h.state_mut().tab = tab;
        h.state_mut().outcome = None;
        h.step();
        h.get_by_label(button).click();
        h.step();
        assert!(h.state().running.is_some(), "{button}");
        // Its progress, in device time (a tenth of the wall's).
        let going = step_until(&mut h, srv.wall(0.05, 10.0), |a| {
            a.running
                .as_ref()
                .is_some_and(|r| r.total > 0.0 && r.done > 0.02)
        });
        assert!(
            going,
            "{button}: {:?} {:?}",
            h.state().running,
            h.state().log
        );
        // On the window (1400 px wide), not beyond its edge where a click does not reach it
        // (the frequency response's Stop was, until its row wrapped).
        assert!(h.get_by_label("Stop").rect().max.x <= 1400.0, "{button}");
        h.get_by_label("Stop").click();
        let ended = step_until(&mut h, srv.wall(0.1, 10.0), |a| a.outcome.is_some());
        assert!(
            ended,
            "{button}: {:?} {:?}",
            h.state().running,
            h.state().log
        );
        let out = h.state().outcome.clone().unwrap();
        assert!(
            matches!(&out, Err(e) if e.contains("stopped")),
            "{button}: {out:?}"
        );
        assert!(
            step_until(&mut h, srv.wall(0.1, 5.0), |a| a.status.is_some()
                && !a.bridge_on()),
            "{button}"
        );
    }
}
