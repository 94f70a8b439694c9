//! Learning from repetition on the virtual device (issue 30): the paper's sine test played
//! from the device's tables, the correction learned after each period
//! (`gms_bench::learn`), against the simulated true position the device never sees. Run with
//! `--nocapture --test-threads=1` for the curves.

use gms_bench::learn::{self, LearnPlan, Path};
use hil_sim::device::LocalDevice;
use hil_sim::learn::{IterationTruth, learn_once};
use hil_sim::scenario::Scenario;

type Curve = Vec<(f64, f64, f64, f64)>;

/// Each iteration: (device RMS, device peak, the device's RMS recomputed from the recording
/// of every step, RMS against the true position).
fn run(sc: &str, plan: &LearnPlan) -> (Curve, hil_sim::learn::LearnRun) {
    let sc = Scenario::parse(sc, "learn").unwrap();
    let r = learn_once(&sc, sc.plant.seed, plan).unwrap();
    (curve(&r), r)
}

/// The run's iterations as a [`Curve`].
fn curve(r: &hil_sim::learn::LearnRun) -> Curve {
    r.iterations
        .iter()
        .map(|t: &IterationTruth| (t.rms, t.peak, t.rms_recorded, t.true_rms))
        .collect()
}

fn print(name: &str, c: &[(f64, f64, f64, f64)]) {
    eprintln!("{name}: iteration, RMS [counts], peak [counts], true RMS [counts]");
    for (i, (rms, peak, _, truth)) in c.iter().enumerate() {
        eprintln!("  {i:2} {rms:7.3} {peak:7.2} {truth:7.3}");
    }
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = v.collect();
    v.iter().sum::<f64>() / v.len() as f64
}

/// The table played without learning (a gain of 1e-9: no correction to speak of) for ten
/// periods after the first: the level the learning is held against, averaged over periods
/// (one period's RMS scatters by ±15 % on this plant: its reversals' stick-slip is not the
/// same twice). Returns the mean (device RMS, peak, true RMS).
fn baseline(sc: &str) -> (f64, f64, f64) {
    let plan = LearnPlan {
        gain: 1e-9,
        ..LearnPlan::default()
    };
    let (c, _) = run(sc, &plan);
    let avg = |k: usize| mean(c[1..].iter().map(|r| [r.0, r.1, r.3][k]));
    (avg(0), avg(1), avg(2))
}

/// GMS + ILC on the default virtual device's sine test (the demo's 0.05 rad, 1 Hz sinusoid
/// with its reversals; the plant's friction drawn within ±15 % of the model's, sense noise
/// on): the device's per-period RMS is what the recording of every step gives; the learning
/// lowers the error against both the reading and the true position, iterations 6-10 against
/// ten periods of GMS alone.
#[test]
fn gms_and_ilc_on_the_paper_sine() {
    let (c, l) = run("", &LearnPlan::default());
    print("GMS + ILC", &c);
    assert_eq!(l.iterations.len(), 11);
    assert!(l.stopped.is_none());
    for (rms, _, recomputed, _) in &c {
        assert!(
            (rms - recomputed).abs() < 1e-3 * rms,
            "{rms} against {recomputed}"
        );
    }
    let (rms0, peak0, true0) = baseline("");
    let tail = |k: usize| mean(c[6..].iter().map(|r| [r.0, r.1, r.3][k]));
    eprintln!(
        "GMS alone (10 periods): {rms0:.3} counts RMS ({true0:.3} true), peak {peak0:.1}; \
         GMS + ILC iterations 6-10: {:.3} ({:.3} true), peak {:.1}; iteration 10: {:.3}; the \
         issue's target 0.5 counts, peak 3",
        tail(0),
        tail(2),
        tail(1),
        c[10].0
    );
    assert!(tail(0) < 0.85 * rms0, "{rms0} → {}", tail(0));
    assert!(tail(2) < 0.85 * true0, "{true0} → {}", tail(2));
    assert!(tail(1) < peak0, "peak {peak0} → {}", tail(1));
}

/// What each part contributes: ILC alone (`ff.mode none`) starts from the uncompensated
/// friction's error and learns most of it away, but GMS + ILC is lower at the first pass and
/// after ten iterations.
#[test]
fn what_gms_and_ilc_each_contribute() {
    let none = "[controller.ff]\nmode = \"none\"\n";
    let (alone, _) = run(none, &LearnPlan::default());
    let (both, _) = run("", &LearnPlan::default());
    print("ILC alone", &alone);
    print("GMS + ILC", &both);
    let reach = alone.iter().position(|r| r.0 <= both[0].0);
    eprintln!(
        "ILC alone reaches GMS's first pass ({:.3}) at iteration {reach:?}",
        both[0].0
    );
    let tail = |c: &Curve| mean(c[8..].iter().map(|r| r.0));
    // Measured (seed 1): first passes 1.509 and 0.535 counts (the stiff 20 kHz loop holds
    // the uncompensated friction to 2.8 times the compensated error; the earlier 10 kHz loop
    // to 5.7 times); ILC alone reaches GMS's first pass at iteration 6.
    assert!(
        alone[0].0 > 2.5 * both[0].0,
        "first passes {} {}",
        alone[0].0,
        both[0].0
    );
    assert!(
        tail(&alone) < 0.5 * alone[0].0,
        "ILC alone {} → {}",
        alone[0].0,
        tail(&alone)
    );
    assert!(
        tail(&both) < tail(&alone),
        "{} against {}",
        tail(&both),
        tail(&alone)
    );
}

/// The targets (0.5 counts RMS, 3 counts peak after ten iterations) on the default
/// virtual device (its position loop at the current loop's rate, 20 kHz, kp 0.7, ki 600,
/// kd 2.7e-4, the derivative's filter at 8 kHz) with the default learning (γ 0.3, Q at
/// 400 Hz): on four friction draws every draw's RMS over iterations 8-10 is within the
/// target, against the reading and the true position, and so is the peak averaged over them.
/// (The earlier 10 kHz loop, kp 0.2, stopped at 0.84 counts: docs/learning.md.)
#[test]
fn the_targets_on_the_default_virtual_device() {
    let sc = Scenario::parse("", "learn").unwrap();
    let plan = LearnPlan::default();
    let runs = hil_sim::learn::learn_draws(&sc, 4, 1, &plan, 2).unwrap();
    let mut peaks = Vec::new();
    for r in &runs {
        let c = curve(r);
        print(&format!("seed {}", r.seed), &c);
        assert!(r.stopped.is_none(), "{:?}", r.stopped);
        let tail = |k: usize| mean(c[8..].iter().map(|r| [r.0, r.1, r.3][k]));
        assert!(c[0].0 > tail(0), "first pass {} → {}", c[0].0, tail(0));
        assert!(tail(0) <= 0.5, "seed {}: RMS {}", r.seed, tail(0));
        assert!(tail(2) <= 0.5, "seed {}: true RMS {}", r.seed, tail(2));
        peaks.push(tail(1));
    }
    let peak = mean(peaks.iter().copied());
    eprintln!("peaks over iterations 8-10 {peaks:.2?}, mean {peak:.2}");
    assert!(peak <= 3.0, "{peaks:?}");
}

/// What the bench reports as not repeating (from the device's figures over the last five
/// iterations: the error at the points and the periods' RMS) against what the recording of
/// every step shows when the best correction is played five periods more: within the
/// bench's known bias, which counts what repeats finer than a point (1 ms) as scatter.
#[test]
fn the_bench_sees_what_does_not_repeat() {
    let sc = Scenario::parse("", "learn").unwrap();
    let runs = hil_sim::learn::learn_draws(&sc, 4, 1, &LearnPlan::default(), 2).unwrap();
    for r in &runs {
        let (rep, nonrep) = r.bench_repeat.unwrap();
        let s = r.scatter;
        eprintln!(
            "seed {}: bench repeating {rep:.3}, not {nonrep:.3}; the steps of 5 periods \
             repeating {:.3}, not {:.3} (true {:.3}, {:.3})",
            r.seed, s.repeating, s.not_repeating, s.true_repeating, s.true_not_repeating
        );
        let ratio = nonrep / s.not_repeating;
        assert!((0.9..1.35).contains(&ratio), "seed {}: {ratio}", r.seed);
        assert!(rep <= s.repeating + 0.15, "seed {}: {rep}", r.seed);
        // The parts' squares make the whole; the truth scatters less than the reading by
        // about its quantisation.
        let whole = s.repeating.powi(2) + s.not_repeating.powi(2);
        assert!((whole - s.rms.powi(2)).abs() < 1e-9 * whole);
        assert!(s.true_not_repeating < s.not_repeating);
    }
}

/// A slow link: every request costs `delay` seconds of device time before the device sees it
/// (a UART, a loaded host, the image on emulated silicon). With 20 ms a request, reading a
/// period's error (16 requests) takes a third of a second and uploading a correction (126)
/// two and a half: several periods of a 1 Hz sine, fifty of a 20 Hz one.
struct SlowLink<'a> {
    dev: &'a mut LocalDevice,
    delay: f64,
}

impl gms_link::DeviceLink for SlowLink<'_> {
    fn request(
        &mut self,
        c: gms_core::protocol::Command<'_>,
    ) -> Result<(Vec<String>, String), gms_link::Error> {
        self.dev.run(self.delay);
        self.dev.request(c)
    }

    fn pass(&mut self, seconds: f64) -> Result<(), gms_link::Error> {
        self.dev.pass(seconds)
    }
}

/// Learns `plan` over a link that adds `delay` \[s\] of device time to every request, every
/// step recorded; checks that each iteration's error at the points is the mean over its bins
/// of the steps recorded in the one period the host names (and that its RMS is that period's,
/// from every step), whatever the periods that passed while the host read and uploaded.
/// Returns the learning.
fn learn_over_a_slow_link(sc: &str, plan: &LearnPlan, delay: f64) -> learn::Learned {
    let sc = Scenario::parse(sc, "learn").unwrap();
    let mut dev = LocalDevice::new(&sc).unwrap();
    dev.record_truth();
    let mut link = SlowLink {
        dev: &mut dev,
        delay,
    };
    let l = learn::learn(&mut link, plan, |_| {}, false).unwrap();
    let truth = dev.take_truth();
    let t = l.table.as_ref().unwrap();
    let (points, steps) = (t.points as usize, t.steps as u64);
    assert_eq!(l.errors.len(), plan.iterations + 1);
    for ((e, p), it) in l.errors.iter().zip(&l.periods).zip(&l.iterations) {
        let from = l.started + u64::from(*p) * points as u64 * steps;
        let lo = truth.partition_point(|r| r.steps < from);
        let period = &truth[lo..lo + points * steps as usize];
        assert_eq!(period[0].steps, from);
        for k in 0..points {
            let bin = &period[k * steps as usize..(k + 1) * steps as usize];
            let mean = bin.iter().map(|r| r.device_error()).sum::<f64>() / steps as f64;
            assert!(
                (e[k] - mean).abs() < 1e-3,
                "period {p} point {k}: {} against {mean}",
                e[k]
            );
        }
        let ms = period.iter().map(|r| r.device_error().powi(2)).sum::<f64>() / period.len() as f64;
        assert!(
            (it.rms - ms.sqrt()).abs() < 1e-3 * it.rms,
            "period {p}: RMS {} against {}",
            it.rms,
            ms.sqrt()
        );
    }
    l
}

/// The error the host learns from is one whole period's, the first played with each
/// correction, however slow the link: with 20 ms a request the 1 Hz sine loses periods while
/// the host reads and uploads (the device holds the period until the host has it), and each
/// iteration's error and RMS are those of the period the host names.
#[test]
fn the_period_is_held_until_a_slow_link_has_read_it() {
    let plan = LearnPlan {
        iterations: 3,
        ..LearnPlan::default()
    };
    let l = learn_over_a_slow_link("", &plan, 0.02);
    eprintln!("periods learned from: {:?}", l.periods);
    // Periods passed while the host read and uploaded (a fast link learns from every other).
    assert!(
        l.periods.windows(2).all(|w| w[1] > w[0] + 2),
        "{:?}",
        l.periods
    );
}

/// A fast scan, a 20 Hz sine (50 ms periods: some eighty pass while a correction goes up a
/// 20 ms link), learnt by ILC alone (no friction feedforward: an error that repeats): the
/// learning completes, learns from one whole period each time, and takes the error down.
#[test]
fn a_20_hz_sine_learns_over_a_slow_link() {
    let plan = LearnPlan {
        path: Path::Sine {
            amplitude: 0.02,
            freq: 20.0,
        },
        iterations: 6,
        ..LearnPlan::default()
    };
    let l = learn_over_a_slow_link("[controller.ff]\nmode = \"none\"\n", &plan, 0.02);
    let rms: Vec<f64> = l.iterations.iter().map(|i| i.rms).collect();
    eprintln!("20 Hz: periods {:?}, RMS {rms:.3?}", l.periods);
    assert!(l.stopped.is_none(), "{:?}", l.stopped);
    assert!(
        l.periods.windows(2).all(|w| w[1] > w[0] + 20),
        "{:?}",
        l.periods
    );
    let tail = mean(rms[4..].iter().copied());
    assert!(tail < 0.4 * rms[0], "{rms:?}");
}

/// Fifty iterations with twice the default sense noise: the period's RMS scatters, the learning
/// neither diverges nor stops, and its last ten stay below GMS alone's level under the same
/// noise.
#[test]
fn fifty_iterations_with_noise_do_not_diverge() {
    let sc = "[plant]\nadc_noise = 0.3e-3\n";
    let plan = LearnPlan {
        iterations: 50,
        ..LearnPlan::default()
    };
    let (c, l) = run(sc, &plan);
    print("50 iterations, noise 0.3 mA", &c);
    assert!(l.stopped.is_none(), "{:?}", l.stopped);
    assert_eq!(c.len(), 51);
    let (rms0, _, _) = baseline(sc);
    let tail = mean(c[41..].iter().map(|r| r.0));
    let worst = c[1..].iter().map(|r| r.0).fold(0.0, f64::max);
    eprintln!("GMS alone {rms0:.3}; iterations 41-50 {tail:.3}, worst {worst:.3}");
    assert!(tail < 0.85 * rms0);
    assert!(worst < 1.3 * rms0);
}

/// The friction drifting up 10 % during the learning (a ramp over 20 s): the error stays
/// bounded and the learning follows it.
#[test]
fn a_drifting_friction_stays_bounded() {
    let sc = "[plant.drift]\nkind = \"ramp\"\namount = 0.1\ntime = 20.0\n";
    let plan = LearnPlan {
        iterations: 16,
        ..LearnPlan::default()
    };
    let (c, l) = run(sc, &plan);
    print("friction +10 % over 20 s", &c);
    assert!(l.stopped.is_none());
    let (rms0, _, _) = baseline(sc);
    let worst = c[1..].iter().map(|r| r.0).fold(0.0, f64::max);
    let tail = mean(c[12..].iter().map(|r| r.0));
    eprintln!(
        "GMS alone {rms0:.3} (the drift's first 20 s); worst {worst:.3}, iterations 12-16 {tail:.3}"
    );
    assert!(worst < 1.3 * rms0);
    assert!(tail < 0.85 * rms0);
}

/// A path beyond the soft limits, and one with a jump, are refused by the device when the
/// table is set — before anything moves.
#[test]
fn a_path_beyond_the_limits_is_refused_before_anything_moves() {
    let sc = Scenario::parse("", "learn").unwrap();
    let mut dev = LocalDevice::new(&sc).unwrap();
    let theta0 = dev.plant().theta;
    // 10 rad/s at most, to 60 rad: beyond the default ±50 rad.
    let beyond = Path::Trajectory(vec![(0.0, 0.0), (3.0, 30.0), (6.0, 60.0), (12.0, 0.0)]);
    let jump = Path::Trajectory(vec![
        (0.0, 0.0),
        (0.5, 0.0),
        (0.5001, 0.5),
        (0.9, 0.5),
        (1.0, 0.0),
    ]);
    for (path, why) in [(beyond, "soft limits"), (jump, "jump")] {
        let plan = LearnPlan {
            path,
            ..LearnPlan::default()
        };
        let e = learn::learn(&mut dev, &plan, |_| {}, false).unwrap_err();
        assert!(e.to_string().contains(why), "{e}");
        let moved = (dev.plant().theta - theta0).abs() / 3.8e-6;
        assert!(moved < 2.0, "moved {moved} counts");
        let st = gms_bench::status(&mut dev).unwrap();
        assert!(!st.enabled, "the bridge as it was (off)");
    }
}

fn ok(dev: &mut LocalDevice, line: &str) -> String {
    let r = dev.ask(line);
    assert!(r.lines().last().unwrap().starts_with("ok"), "{line}: {r}");
    r
}

fn refused(dev: &mut LocalDevice, line: &str, why: &str) {
    let r = dev.ask(line);
    let last = r.lines().last().unwrap();
    assert!(last.starts_with("err") && last.contains(why), "{line}: {r}");
}

fn state(dev: &mut LocalDevice) -> String {
    let r = ok(dev, "table");
    r.split_whitespace()
        .find_map(|w| w.strip_prefix("state="))
        .unwrap()
        .to_string()
}

/// The table's commands on the device: bad input refused with its reason and nothing
/// changed; a run only from the table's start with the loop holding; `disable` ends a run at
/// once, a lost link at the period's end (holding at the table's start).
#[test]
fn table_commands_refuse_bad_input_and_end_safely() {
    let sc = Scenario::parse("", "learn").unwrap();
    let mut dev = LocalDevice::new(&sc).unwrap();
    refused(&mut dev, "table run 2", "no table set");
    refused(&mut dev, "table corr 0 0", "no table set");
    refused(&mut dev, "table ref 4 1", "from point 0");
    refused(&mut dev, "table ref 0 1 nan", "a value is a number");
    refused(&mut dev, "table ref 0 1 2 3 4 5 6 7 8 9", "at most 8");
    // A 16-point triangle, 100 counts high, 100 steps between points.
    let pts: Vec<String> = (0..16)
        .map(|k| format!("{}", 100.0 - (12.5 * (k as f64 - 8.0)).abs()))
        .collect();
    for (i, c) in pts.chunks(8).enumerate() {
        ok(&mut dev, &format!("table ref {} {}", i * 8, c.join(" ")));
    }
    refused(&mut dev, "table set 16 0 0", "POINTS from 4");
    refused(&mut dev, "table set 17 100 0", "not written whole");
    refused(&mut dev, "table set 16 100 999999999999", "soft limits");
    ok(&mut dev, "table set 16 100 0");
    assert_eq!(state(&mut dev), "ready");
    refused(&mut dev, "table read err 0 4", "no period complete");
    refused(&mut dev, "table run 2", "disabled");
    ok(&mut dev, "enable");
    // The table starts at 0 from count 0 (the power-up position): move away, refused.
    ok(&mut dev, "move 0.01");
    dev.run(0.5);
    refused(&mut dev, "table run 2", "not at the table's start");
    ok(&mut dev, "move 0");
    dev.run(0.5);
    // A correction beyond the drive's torque, out of order, or not whole.
    refused(&mut dev, "table corr 0 1", "torque");
    ok(&mut dev, "table corr 0 1e-6 2e-6");
    refused(&mut dev, "table use", "not written whole");
    ok(&mut dev, "table run 1000");
    assert_eq!(state(&mut dev), "playing");
    refused(&mut dev, "table ref 0 1", "playing");
    refused(&mut dev, "table clear", "playing");
    refused(&mut dev, "table run 2", "already playing");
    dev.run(0.4);
    ok(&mut dev, "table read err 0 16");
    // Five periods of 80 ms played: the first is held (`held=1`), until `table next`.
    let field = |t: &str, k: &str| -> u32 {
        t.split_whitespace()
            .find_map(|w| w.strip_prefix(k)?.parse().ok())
            .unwrap_or_else(|| panic!("{k} in {t}"))
    };
    let t = ok(&mut dev, "table");
    assert!(field(&t, "period=") >= 4, "{t}");
    assert_eq!((field(&t, "done="), field(&t, "held=")), (0, 1), "{t}");
    ok(&mut dev, "table next");
    dev.run(0.2);
    let t = ok(&mut dev, "table");
    assert!(field(&t, "done=") >= 5 && field(&t, "held=") == 1, "{t}");
    // `disable`: the run ends at once, the bridge off.
    ok(&mut dev, "disable");
    assert_eq!(state(&mut dev), "ready");
    // A lost link: the run ends at the end of its period; the axis holds at the start.
    ok(&mut dev, "enable");
    ok(&mut dev, "move 0");
    dev.run(0.5);
    ok(&mut dev, "table run 1000");
    dev.run(0.25);
    dev.disconnect();
    assert_eq!(state(&mut dev), "playing", "until the period's end");
    dev.run(0.2);
    assert_eq!(state(&mut dev), "ready");
    let st = gms_bench::status(&mut dev).unwrap();
    assert!(st.enabled && !st.moving);
    assert!(
        st.pos.abs() / 3.8e-6 < 3.0,
        "holding at the start: {} rad",
        st.pos
    );
    ok(&mut dev, "table clear");
    assert_eq!(state(&mut dev), "empty");
    // Set again, then the position rate changes: the table (its steps and speeds checked for
    // the old rate) is forgotten.
    for (i, c) in pts.chunks(8).enumerate() {
        ok(&mut dev, &format!("table ref {} {}", i * 8, c.join(" ")));
    }
    ok(&mut dev, "table set 16 100 0");
    assert_eq!(state(&mut dev), "ready");
    ok(&mut dev, "set rate.pos_hz 5000");
    assert_eq!(state(&mut dev), "empty");
    refused(&mut dev, "table run 1", "no table set");
}
