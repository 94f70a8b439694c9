//! The plant's real bridge, supply and sense chain (`[plant.bridge]`, `[plant.supply]`,
//! `[plant.sense]`) against what their physics gives by hand: the period's mean voltage with
//! the dead time on the side the current's direction puts it, the pulse's delay, a pulse
//! that runs past its period's end, the supply's sag, the amplifier's lag, and the energy
//! balance with the switches' losses in it.

use gms_core::control::controller::FfMode;
use hil_sim::plant::Plant;
use hil_sim::scenario::Scenario;
use hil_sim::sim;

/// 40 kHz, the default current loop's period \[s\].
const T: f64 = 25e-6;

/// The default scenario with the real bridge at the DRV8871's figures, its switching node
/// switched at once (the binary model, `c_node_f` 0: the closed forms below are its), and a
/// stiff supply, the device's dead-time compensation off (`drive.dead_time` 0; the default
/// plant's device compensates it).
fn real() -> Scenario {
    let mut sc = Scenario::default();
    sc.plant.bridge.ideal = false;
    sc.plant.bridge.dead_time_s = 220e-9;
    sc.plant.bridge.delay_s = 0.7e-6;
    sc.plant.bridge.c_node_f = 0.0;
    sc.plant.supply.r_source_ohm = 0.0;
    sc.controller.insert(
        "drive".into(),
        toml::Value::Table(toml::toml! { dead_time = 0.0 }),
    );
    sc.check().unwrap();
    assert_eq!(sc.controller_params().unwrap().dead_time, 0.0);
    sc
}

/// One period of `duty` in `n` steps with the current held at `amps` at each step's start
/// (the bridge's voltage depends on the current's direction alone): the voltage's mean over
/// the period \[V\] and its centroid in time \[s from the period's start\].
fn period_with_current(p: &mut Plant, duty: f64, amps: f64, n: usize) -> (f64, f64) {
    p.start_period(duty, T);
    let dt = T / n as f64;
    let (mut area, mut moment) = (0.0, 0.0);
    for k in 0..n {
        p.i = amps;
        p.step(dt);
        area += p.voltage * dt;
        moment += p.voltage * dt * (k as f64 + 0.5) * dt;
    }
    (area / T, moment / area)
}

#[test]
fn the_dead_time_takes_its_side_from_the_currents_direction() {
    let sc = real();
    let mut p = Plant::new(&sc.plant, 1).unwrap();
    let v = sc.plant.supply.volts;
    let td = sc.plant.bridge.dead_time_s;
    // Two periods each: the first one's pulse ends in the second (the delay), so that the
    // second is the steady period.
    for (duty, amps) in [(0.2, 0.1), (0.2, -0.1), (-0.2, -0.1), (-0.2, 0.1)] {
        period_with_current(&mut p, duty, amps, 250);
        let (mean, _) = period_with_current(&mut p, duty, amps, 250);
        // Along the drive: the dead time is the brake's; against it, the drive's.
        let along = duty * amps > 0.0;
        let expect = duty * v - f64::signum(duty) * if along { td } else { -td } / T * v;
        assert!(
            (mean - expect).abs() < 1e-9,
            "duty {duty}, current {amps}: {mean} V against {expect}"
        );
    }
    // The step at a reversal: 2 t_dead / T × V, 0.211 V at 12 V and 40 kHz.
    period_with_current(&mut p, 0.2, 0.1, 250);
    let (pos, _) = period_with_current(&mut p, 0.2, 0.1, 250);
    period_with_current(&mut p, 0.2, -0.1, 250);
    let (neg, _) = period_with_current(&mut p, 0.2, -0.1, 250);
    let step = neg - pos;
    assert!((step - 2.0 * td / T * v).abs() < 1e-9, "{step}");
    assert!((step - 0.2112).abs() < 1e-4, "{step}");

    // The ideal bridge: duty × supply, whatever the current.
    let mut sc = real();
    sc.plant.bridge.ideal = true;
    let mut p = Plant::new(&sc.plant, 1).unwrap();
    for amps in [0.1, -0.1] {
        let (mean, _) = period_with_current(&mut p, 0.2, amps, 10);
        assert!((mean - 0.2 * v).abs() < 1e-12, "{mean}");
    }
}

/// With a switching node's capacitance (`c_node_f`), the dead time's loss goes through zero
/// current continuously: the current slews the node at i / C during the dead time, so the
/// period's mean voltage is `(d − sign(i) · t_dead · s(|i|) / T) · V`, s the share of the
/// ramp: |i| t_dead / (2 C V) until the node reaches the rail within the dead time, then
/// 1 − C V / (2 |i| t_dead). 0 F gives the binary model's step at any current, however small.
#[test]
fn a_node_capacitance_makes_the_dead_time_continuous_through_zero_current() {
    let (td, v, c, d) = (220e-9, 12.0, 100e-12, 0.3);
    let share = |amps: f64| {
        let q = amps * td / (c * v);
        if q >= 1.0 { 1.0 - 0.5 / q } else { 0.5 * q }
    };
    for amps in [0.1, 0.01, 0.002, 1e-6, -1e-6, -0.002, -0.01, -0.1] {
        let mut sc = real();
        sc.plant.bridge.c_node_f = c;
        // A winding slow enough that the current held at each step's start is the current
        // at the edges within it (12 nA of change in a 10 ns step).
        sc.plant.inductance = 10.0;
        sc.check().unwrap();
        let mut p = Plant::new(&sc.plant, 1).unwrap();
        let (mean, _) = period_with_current(&mut p, d, amps, 2500);
        let expect = (d - f64::signum(amps) * td * share(amps.abs()) / T) * v;
        assert!(
            (mean - expect).abs() < 1e-6,
            "{amps} A: {mean} V against {expect}"
        );
    }
    // The binary model (0 F): the full step from the smallest current on.
    let mut p = Plant::new(&real().plant, 1).unwrap();
    let (mean, _) = period_with_current(&mut p, d, 1e-6, 2500);
    assert!((mean - (d - td / T) * v).abs() < 1e-9, "{mean}");
    // Out of range: refused.
    let mut sc = real();
    sc.plant.bridge.c_node_f = 1e-6;
    assert!(
        sc.check()
            .unwrap_err()
            .to_string()
            .contains("plant.bridge.c_node_f")
    );
}

#[test]
fn the_pulse_is_centred_on_the_counters_top_after_the_delay() {
    let sc = real();
    let mut p = Plant::new(&sc.plant, 1).unwrap();
    let (td, delay) = (sc.plant.bridge.dead_time_s, sc.plant.bridge.delay_s);
    period_with_current(&mut p, 0.3, 0.1, 500);
    let (_, centroid) = period_with_current(&mut p, 0.3, 0.1, 500);
    // The pulse runs from T/2 − w/2 + delay + t_dead to T/2 + w/2 + delay: its centre is
    // T/2 + delay + t_dead / 2. The steps' centroid is within a step's half (25 ns).
    let expect = T / 2.0 + delay + td / 2.0;
    assert!(
        (centroid - expect).abs() < 25e-9,
        "{centroid} s against {expect} s"
    );
}

#[test]
fn a_pulse_delayed_past_its_periods_end_drives_the_next_one() {
    let sc = real();
    let mut p = Plant::new(&sc.plant, 1).unwrap();
    let (v, td, delay) = (
        sc.plant.supply.volts,
        sc.plant.bridge.dead_time_s,
        sc.plant.bridge.delay_s,
    );
    // At 0.98 the pulse ends 0.25 µs before the period's end, 0.45 µs after it once delayed.
    // Every period's mean is still its own pulse's (less the dead time).
    period_with_current(&mut p, 0.98, 0.1, 250);
    let (mean, _) = period_with_current(&mut p, 0.98, 0.1, 250);
    let expect = (0.98 - td / T) * v;
    assert!((mean - expect).abs() < 1e-9, "{mean} against {expect}");
    // The period after a full pulse's last one, at duty 0: only the spill-over drives.
    let (spill, _) = period_with_current(&mut p, 0.0, 0.1, 250);
    let expect = (delay - 0.01 * T) / T * v;
    assert!((spill - expect).abs() < 1e-9, "{spill} against {expect}");
    // At full duty the outputs never switch: no dead time at all.
    period_with_current(&mut p, 1.0, 0.1, 250);
    let (full, _) = period_with_current(&mut p, 1.0, 0.1, 250);
    assert!((full - v).abs() < 1e-9, "{full}");
}

#[test]
fn the_supply_sags_under_the_current_it_delivers() {
    let mut sc = Scenario::default();
    sc.plant.bridge.ideal = true;
    sc.plant.supply.r_source_ohm = 1.0;
    sc.check().unwrap();
    let mut p = Plant::new(&sc.plant, 1).unwrap();
    // Half the period driving 0.2 A: the supply delivers 0.1 A on average, 0.1 V lost.
    let (mean, _) = period_with_current(&mut p, 0.5, 0.2, 10);
    assert!((mean - 0.5 * (12.0 - 0.1)).abs() < 1e-12, "{mean}");
    // Braking a current (driving against it) pushes it back into the supply: it rises.
    let (mean, _) = period_with_current(&mut p, 0.5, -0.2, 10);
    assert!((mean - 0.5 * (12.0 + 0.1)).abs() < 1e-12, "{mean}");
}

#[test]
fn the_sense_amplifier_lags_by_its_bandwidth() {
    // A held rotor (no back-EMF) and a voltage step: i = I (1 − e^(−t/τe)); through a first-
    // order lag τs the reading is I (1 − (τe e^(−t/τe) − τs e^(−t/τs)) / (τe − τs)).
    let mut sc = Scenario::default();
    // The ideal bridge: the step's voltage from its start, the winding's resistance alone.
    sc.plant.bridge.ideal = true;
    sc.plant.k_e = 0.0;
    sc.plant.adc_noise = 0.0;
    sc.plant.sense.bandwidth_hz = 20e3;
    sc.plant.supply.r_source_ohm = 0.0;
    sc.check().unwrap();
    let mut p = Plant::new(&sc.plant, 1).unwrap();
    let r = sc.plant.resistance;
    let tau_e = sc.plant.inductance / r;
    let tau_s = 1.0 / (2.0 * std::f64::consts::PI * 20e3);
    let big_i = 0.1 * sc.plant.supply.volts / r;
    // Steps of a fifth of τs: the lag follows the current's exponential exactly within each.
    let dt = 0.2 * tau_s;
    p.start_period(0.1, 1.0);
    let mut worst = 0.0f64;
    for k in 1..=500 {
        p.step(dt);
        let t = k as f64 * dt;
        let expect = big_i
            * (1.0 - (tau_e * (-t / tau_e).exp() - tau_s * (-t / tau_s).exp()) / (tau_e - tau_s));
        worst = worst.max((p.sense(0.0) - expect).abs());
    }
    // Exact to rounding (stepping the lag on each step's end current instead was off by
    // (I / τe) dt / 2 = 1.2 mA here, 2.6e-5 A at 5 ns steps).
    assert!(worst < 1e-9, "{worst} A");
    // Unlimited (0 Hz): the reading is the current.
    sc.plant.sense.bandwidth_hz = 0.0;
    let mut p = Plant::new(&sc.plant, 1).unwrap();
    p.start_period(0.1, 1.0);
    p.step(1e-6);
    assert_eq!(p.sense(0.0), p.i);
}

/// The real bridge's current is exact whatever the plant's steps: its pulses' edges fall
/// inside steps, and the winding is integrated piece by piece between them, so the reading at
/// the counter's bottom (the brake's middle, where the sense converts) is the same at 10 steps
/// a period as at 250. (Averaging each step's voltage instead moved a pulse's charge within
/// its step: the reading at 10 steps was 0.48 % above the one at 200 on the default motor.)
#[test]
fn the_reading_does_not_depend_on_the_plants_steps() {
    let mut sc = real();
    sc.plant.inertia = 1e3; // the rotor held: no back-EMF
    sc.plant.adc_noise = 0.0;
    sc.check().unwrap();
    let reading = |n: usize| {
        let mut p = Plant::new(&sc.plant, 1).unwrap();
        let mut last = 0.0;
        for _ in 0..400 {
            p.start_period(0.02, T);
            last = p.sense(0.0);
            for _ in 0..n {
                p.step(T / n as f64);
            }
        }
        last
    };
    let (coarse, fine) = (reading(10), reading(250));
    // About 12.8 mA (0.02 of 12 V, less the dead time, over 10.565 Ω).
    assert!((0.012..0.014).contains(&fine), "{fine} A");
    assert!(
        (coarse / fine - 1.0).abs() < 1e-6,
        "{coarse} against {fine} A"
    );
}

#[test]
fn the_amplifiers_swing_keeps_the_adc_off_its_end_codes() {
    let sc = Scenario::default();
    // 0.05 V of a 3.3 V span: 62 codes short of each end.
    let (lo, hi) = sc.plant.sense.code_limits(3.3, 4095.0);
    assert!((lo - 0.05 / 3.3 * 4095.0).abs() < 1e-9 && (hi - (4095.0 - lo)).abs() < 1e-9);
    assert!((62.0..63.0).contains(&lo), "{lo}");
}

/// The energy balance closes with the real bridge: its switches' loss is in the copper term,
/// and the input is what the bridge puts into the winding (the supply's sag before it).
#[test]
fn energy_balance_closes_with_the_real_bridge() {
    let mut sc = real();
    sc.plant.supply.r_source_ohm = 0.5;
    sc.check().unwrap();
    crate::common::energy_balance_closes(&sc);
}

/// The median over `seeds` friction draws of the GMS-compensated run's (rms, reversal) error
/// \[rad\].
fn medians(sc: &Scenario, seeds: std::ops::RangeInclusive<u64>) -> (f64, f64) {
    let runs: Vec<_> = seeds
        .map(|seed| sim::run(sc, FfMode::Gms, seed).unwrap().metrics)
        .collect();
    let median = |f: &dyn Fn(&gms_ident::trace::Metrics) -> f64| {
        let mut v: Vec<f64> = runs.iter().map(f).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    (median(&|m| m.rms_error), median(&|m| m.reversal_error))
}

/// The dead time costs the friction compensation its precision at every reversal, and the
/// current step's compensation (`drive.dead_time`, keyed on the commanded current's sign)
/// wins it back: on the default scenario's motion, seven friction draws, medians.
#[test]
fn dead_time_compensation_wins_back_the_reversals() {
    let mut ideal = Scenario::default();
    ideal.plant.bridge.ideal = true;
    // The default plant's switching node.
    let mut real = real();
    real.plant.bridge.c_node_f = Scenario::default().plant.bridge.c_node_f;
    // The default plant's device compensates; set here all the same.
    let mut compensated = real.clone();
    compensated.controller.insert(
        "drive".into(),
        toml::Value::Table(toml::toml! { dead_time = 220e-9 }),
    );
    compensated.check().unwrap();
    assert_eq!(
        compensated.controller_params().unwrap().dead_time,
        220e-9,
        "the scenario sets the parameter"
    );
    let seeds = 1..=7;
    let (rms_i, rev_i) = medians(&ideal, seeds.clone());
    let (rms_r, rev_r) = medians(&real, seeds.clone());
    let (rms_c, rev_c) = medians(&compensated, seeds);
    let c = ideal.plant.rad_per_count;
    eprintln!(
        "rms / reversal [counts]: ideal {:.3} / {:.2}, real {:.3} / {:.2}, compensated {:.3} / {:.2}",
        rms_i / c,
        rev_i / c,
        rms_r / c,
        rev_r / c,
        rms_c / c,
        rev_c / c
    );
    // Uncompensated, the reversal's peak nearly doubles (4.40 -> 8.64 counts, rms 0.398 ->
    // 0.560); compensated it comes back within 15 % of the ideal bridge's (4.63 counts, rms
    // 0.410: 5 % and 3 % over).
    assert!(
        rev_r > 1.3 * rev_i && rms_r > 1.2 * rms_i,
        "the dead time costs nothing?"
    );
    assert!(rev_c < 1.15 * rev_i && rms_c < 1.1 * rms_i, "not won back");
}

/// Commissioning measures the bridge's dead time from the voltage the held currents need
/// through zero (`drive.dead_time`), and the winding's resistance with the switches' in it,
/// whatever the device's compensation is set to; on the ideal bridge it finds none. Against
/// the plant's truth: 220 ns and R + r_on = 10.565 Ω.
#[test]
fn commissioning_measures_the_bridges_dead_time() {
    use gms_bench::commission;
    for (ideal, set) in [(false, 0.0), (false, 220e-9), (true, 0.0)] {
        let text = format!(
            "{}\n[plant.bridge]\nideal = {ideal}\n[controller.drive]\ndead_time = {set:e}\n",
            crate::common::QUIET
        );
        let sc = Scenario::parse(&text, "test").unwrap();
        let truth_r = sc.plant.resistance + if ideal { 0.0 } else { 0.565 };
        let truth_dt = if ideal { 0.0 } else { 220e-9 };
        let mut dev = hil_sim::device::LocalDevice::new(&sc).unwrap();
        let c = commission(&mut dev, 1.0).unwrap();
        for l in c
            .lines
            .iter()
            .filter(|l| l.contains("resistance") || l.contains("dead"))
        {
            eprintln!("  {l}");
        }
        eprintln!(
            "ideal {ideal}, drive.dead_time {set:e}: R {:.4} Ω ({:+.2} %), dead time {:.1} ns",
            c.r,
            (c.r / truth_r - 1.0) * 100.0,
            c.dead_time * 1e9
        );
        assert!((c.r / truth_r - 1.0).abs() < 0.05, "R {}", c.r);
        // The ideal bridge's holds read a fraction of a ns from their noise: none seen, 0 set.
        if ideal {
            assert_eq!(c.dead_time, 0.0);
            assert!(
                c.lines
                    .iter()
                    .any(|l| l.contains("bridge dead time: none seen")),
                "{:?}",
                c.lines
            );
        }
        assert!(
            (c.dead_time - truth_dt).abs() < 0.2 * 220e-9,
            "dead time {} s against {truth_dt}",
            c.dead_time
        );
        assert!(
            c.settings()
                .contains(&(gms_core::protocol::ParamId::DriveDeadTime, c.dead_time)),
            "applied and written with the rest"
        );
        // At 1 rad/s (3 at the top) the default motor's back-EMF is 20 mV, a fifth of the
        // 106 mV the dead time takes: the real bridge's k_e comes with a warning, the ideal's
        // without.
        let warned = c.lines.iter().any(|l| l.contains("k_e is uncertain"));
        assert_eq!(warned, !ideal, "{:?}", c.lines);
    }
}

/// The sense amplifier's recovery after the bridge's edges (`[plant.sense] recovery_s`,
/// `edge_a`): +edge_a for recovery_s from the drive's start (after the delay, and the dead
/// time when the current flows along the drive), −edge_a from its end; nothing between. And
/// the board's duty limit (gms-core's `SenseChain::duty_max`, worked out from the window and
/// the edge's settling) keeps every disturbed instant out of its sense window around the
/// counter's bottom, which a duty above it does not.
#[test]
fn the_amplifier_recovers_after_each_edge_and_the_duty_limit_keeps_it_out_of_the_window() {
    let sc = real();
    let (td, delay) = (sc.plant.bridge.dead_time_s, sc.plant.bridge.delay_s);
    let (rec, a) = (sc.plant.sense.recovery_s, sc.plant.sense.edge_a);
    assert_eq!((rec, a), (1e-6, 0.0147));
    // One period in 2,500 steps of 10 ns after a first one (the spill-over of its pulse): the
    // disturbance after each step, at the step's end.
    let disturbed = |duty: f64| {
        let mut p = Plant::new(&sc.plant, 1).unwrap();
        period_with_current(&mut p, duty, 0.1, 10);
        p.start_period(duty, T);
        let n = 2500;
        let dt = T / n as f64;
        let mut out = Vec::new();
        for k in 0..2 * n {
            if k == n {
                p.start_period(duty, T);
            }
            p.i = 0.1;
            p.step(dt);
            out.push(((k + 1) as f64 * dt, p.edge_disturbance()));
        }
        out
    };
    let d = 0.3;
    let on = T / 2.0 - d * T / 2.0 + delay + td;
    let off = T / 2.0 + d * T / 2.0 + delay;
    for (t, g) in disturbed(d) {
        // Within a step (10 ns) of an interval's ends either way.
        let within = |from: f64| t > from + 10e-9 && t < from + rec - 10e-9;
        let outside = |from: f64| t < from - 10e-9 || t > from + rec + 10e-9;
        let at = t % T;
        if within(on) || within(on + T) {
            assert_eq!(g, a, "at {at}");
        } else if within(off) || within(off + T) {
            assert_eq!(g, -a, "at {at}");
        } else if outside(on) && outside(off) && outside(on + T) && outside(off + T) {
            assert_eq!(g, 0.0, "at {at}");
        }
    }
    // The board's window: centred on the counter's bottom (t = T), w wide.
    let board = gms_core::boards::f405::BOARD.sense;
    let w = board.window_s as f64;
    let limit = board.duty_max(40_000.0) as f64;
    let in_window = |duty: f64| {
        disturbed(duty)
            .iter()
            .filter(|(t, g)| (t - T).abs() <= w / 2.0 && *g != 0.0)
            .count()
    };
    assert_eq!(in_window(limit), 0, "at the limit {limit}");
    assert!(in_window(limit + 0.05) > 0, "above the limit {limit}");
}
