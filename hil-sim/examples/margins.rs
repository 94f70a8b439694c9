//! Issue 41's trade, from the linear model (`gms_ident::linear`, which the device's `frf`
//! matches within 1 dB and 3°): for a grid of position tunes on the default axis, the
//! margins at rest and sliding, worst over the plant variations the issue names (the
//! pre-sliding stiffness ×0.5…×2, the inertia ±20 %). Work in progress (branch wip-41): the
//! tunes it picks are to be checked by `gms-tune frf --loop open` and `hil-sim compare`.
//!
//! `cargo run -p hil-sim --example margins [BW_HZ,...]` (the current loop's bandwidths tried;
//! 1000 by default)

use gms_bench::frf;
use gms_bench::settings;
use gms_ident::linear::{LinearAxis, Operating, SmallSignal};
use hil_sim::device::LocalDevice;
use hil_sim::scenario::Scenario;

fn margins(ss: &SmallSignal, s: &gms_core::protocol::Settings, op: Operating) -> frf::Margins {
    let Ok(lin) = LinearAxis::new(ss, s, op) else {
        return frf::margins(&[]);
    };
    let l: Vec<(f64, num_complex::Complex64)> = (0..600)
        .map(|i| {
            let f = 5.0 * (900.0f64).powf(i as f64 / 599.0);
            let z = lin.open_loop(f);
            (f, num_complex::Complex64::new(z.re, z.im))
        })
        .collect();
    frf::margins(&l)
}

fn main() {
    let mut sc = Scenario::default();
    sc.plant.variability = 0.0;
    let mut dev = LocalDevice::new(&sc).unwrap();
    let s0 = settings::read(&mut dev).unwrap();
    let ss0 = dev.plant().small_signal();
    let variations: Vec<SmallSignal> = [0.5, 1.0, 2.0]
        .iter()
        .flat_map(|&kx| {
            [0.8, 1.0, 1.2].iter().map(move |&jx| SmallSignal {
                k_act: ss0.k_act * kx,
                k_gw: ss0.k_gw * kx,
                j: ss0.j * jx,
                ..ss0
            })
        })
        .collect();
    println!(
        "default: kp {} ki {} kd {} d_filter {} Hz; cur.kp {} cur.ki {}",
        s0.pid.kp, s0.pid.ki, s0.pid.kd, s0.pid.d_filter_hz, s0.current.kp, s0.current.ki
    );
    println!(
        "kp     ki     kd        | nominal rest PM/GM  sliding PM/GM | worst rest PM/GM  sliding PM/GM"
    );
    let mut best: Vec<(f64, String)> = Vec::new();
    // The filters tried: none; a low-pass; a wide notch at the nominal rest resonance
    // (sqrt(Σk / J)); both.
    let f_rest = ((ss0.k_act + ss0.k_gw) / ss0.j).sqrt() / std::f64::consts::TAU;
    println!("nominal rest resonance {f_rest:.0} Hz");
    let shapes: Vec<(String, gms_core::shaping::ShapingParams)> = {
        use gms_core::shaping::{Notch, ShapingParams};
        let mut v = vec![("none".to_string(), ShapingParams::OFF)];
        for lp in [1200.0f32, 2000.0, 3000.0] {
            v.push((
                format!("lp {lp:.0}"),
                ShapingParams {
                    lp_hz: lp,
                    ..ShapingParams::OFF
                },
            ));
        }
        for (q, depth) in [(0.5f32, 10.0f32), (0.7, 15.0), (1.0, 20.0)] {
            let notch = Notch {
                f_hz: f_rest as f32,
                q,
                depth_db: depth,
            };
            v.push((
                format!("notch q{q} {depth:.0}dB"),
                ShapingParams {
                    notch: [notch, Notch::OFF],
                    ..ShapingParams::OFF
                },
            ));
        }
        v
    };
    // The current loop's bandwidth: the default's (kp = ω L, ki = ω R at 1 kHz), or those
    // the first argument lists.
    let bws: Vec<f32> = std::env::args()
        .nth(1)
        .map(|a| a.split(',').filter_map(|x| x.parse().ok()).collect())
        .unwrap_or_else(|| vec![1000.0]);
    for bw in bws {
        let w = std::f32::consts::TAU * bw;
        let cur = (w * ss0.l as f32, w * ss0.r as f32);
        println!("current loop {bw} Hz: cur.kp {} cur.ki {}", cur.0, cur.1);
        for (shape_name, shape) in &shapes {
            for kp in [0.2f32, 0.3, 0.4, 0.5, 0.6, 0.7] {
                for kd in [0.8e-4f32, 1.0e-4, 1.2e-4, 1.5e-4, 1.8e-4, 2.2e-4, 2.7e-4] {
                    for kif in [250.0f32, 500.0, 860.0] {
                        let mut s = s0;
                        s.shaping = *shape;
                        (s.current.kp, s.current.ki) = cur;
                        s.pid.kp = kp;
                        s.pid.kd = kd;
                        s.pid.ki = kp * kif;
                        let nom = (
                            margins(&ss0, &s, Operating::Rest),
                            margins(&ss0, &s, Operating::Sliding),
                        );
                        let mut worst =
                            (f64::INFINITY, f64::INFINITY, f64::INFINITY, f64::INFINITY);
                        for v in &variations {
                            let r = margins(v, &s, Operating::Rest);
                            let sl = margins(v, &s, Operating::Sliding);
                            let pm = |m: &frf::Margins| {
                                if m.phase_margin_deg.is_nan() {
                                    -1.0
                                } else {
                                    m.phase_margin_deg
                                }
                            };
                            worst.0 = worst.0.min(pm(&r));
                            worst.1 = worst.1.min(r.gain_margin_db);
                            worst.2 = worst.2.min(pm(&sl));
                            worst.3 = worst.3.min(sl.gain_margin_db);
                        }
                        let line = format!(
                            "{shape_name:<16} {kp:<6} {:<6.0} {kd:<9.2e} | {:5.1}° {:5.2} dB  {:5.1}° {:5.2} dB | {:5.1}° {:5.2} dB  {:5.1}° {:5.2} dB",
                            s.pid.ki,
                            nom.0.phase_margin_deg,
                            nom.0.gain_margin_db,
                            nom.1.phase_margin_deg,
                            nom.1.gain_margin_db,
                            worst.0,
                            worst.1,
                            worst.2,
                            worst.3
                        );
                        if worst.0 >= 40.0 && worst.1 >= 6.0 && worst.2 >= 40.0 && worst.3 >= 6.0 {
                            best.push((kp as f64, format!("{bw:<5} {line}")));
                        }
                        println!("{bw:<5} {line}");
                    }
                }
            }
        }
    }
    println!("\ntunes with >= 40° and 6 dB in every variation, stiffest first:");
    best.sort_by(|a, b| b.0.total_cmp(&a.0));
    for (_, l) in best.iter().take(30) {
        println!("{l}");
    }
}
