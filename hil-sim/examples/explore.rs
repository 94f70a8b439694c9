use gms_bench::{frf, settings};
use gms_ident::linear::{LinearAxis, Operating, SmallSignal};
use hil_sim::device::LocalDevice;
use hil_sim::scenario::Scenario;
fn margins(ss: &SmallSignal, s: &gms_core::protocol::Settings, op: Operating) -> (f64, f64, f64) {
    let Ok(lin) = LinearAxis::new(ss, s, op) else {
        return (-1.0, -1.0, 0.0);
    };
    let l: Vec<(f64, num_complex::Complex64)> = (0..500)
        .map(|i| {
            let f = 5.0 * (900.0f64).powf(i as f64 / 499.0);
            let z = lin.open_loop(f);
            (f, num_complex::Complex64::new(z.re, z.im))
        })
        .collect();
    let m = frf::margins(&l);
    (
        if m.phase_margin_deg.is_nan() {
            -1.0
        } else {
            m.phase_margin_deg
        },
        m.gain_margin_db,
        m.crossover_hz,
    )
}
fn main() {
    let mut sc = Scenario::default();
    sc.plant.variability = 0.0;
    let mut dev = LocalDevice::new(&sc).unwrap();
    let s0 = settings::read(&mut dev).unwrap();
    let ss0 = dev.plant().small_signal();
    let vars: Vec<(String, SmallSignal)> = [0.5, 1.0, 2.0]
        .iter()
        .flat_map(|&kx| {
            [0.8, 1.0, 1.2].iter().map(move |&jx| {
                (
                    format!("k×{kx} J×{jx}"),
                    SmallSignal {
                        k_act: ss0.k_act * kx,
                        k_gw: ss0.k_gw * kx,
                        j: ss0.j * jx,
                        ..ss0
                    },
                )
            })
        })
        .collect();
    let mut s = s0;
    for a in std::env::args().skip(1) {
        let (k, v) = a.split_once('=').unwrap();
        let v: f32 = v.parse().unwrap();
        match k {
            "kp" => s.pid.kp = v,
            "ki" => s.pid.ki = v,
            "kd" => s.pid.kd = v,
            "df" => s.pid.d_filter_hz = v,
            "ckp" => s.current.kp = v,
            "cki" => s.current.ki = v,
            "r" => s.motor.r = v,
            "lp" => s.shaping.lp_hz = v,
            "rate" => {
                s.pos_rate_hz = v;
                s.cur_rate_hz = v;
            }
            "crate" => s.cur_rate_hz = v,
            _ => panic!("{k}"),
        }
    }
    let nr = margins(&ss0, &s, Operating::Rest);
    let ns = margins(&ss0, &s, Operating::Sliding);
    let mut w = (
        999.0f64,
        999.0f64,
        999.0f64,
        999.0f64,
        String::new(),
        String::new(),
    );
    for (n, v) in &vars {
        let r = margins(v, &s, Operating::Rest);
        let sl = margins(v, &s, Operating::Sliding);
        if r.0 < w.0 {
            w.0 = r.0;
            w.4 = n.clone();
        }
        w.1 = w.1.min(r.1);
        if sl.0 < w.2 {
            w.2 = sl.0;
            w.5 = n.clone();
        }
        w.3 = w.3.min(sl.1);
    }
    println!(
        "nominal rest {:5.1}° {:5.2} dB (fc {:.0})  sliding {:5.1}° {:5.2} dB (fc {:.0}) | worst rest {:5.1}° {:5.2} dB [{}]  sliding {:5.1}° {:5.2} dB [{}]",
        nr.0, nr.1, nr.2, ns.0, ns.1, ns.2, w.0, w.1, w.4, w.2, w.3, w.5
    );
}
#[allow(dead_code)]
fn peak(ss: &SmallSignal, s: &gms_core::protocol::Settings) -> (f64, f64) {
    let lin = LinearAxis::new(ss, s, Operating::Sliding).unwrap();
    (0..400)
        .map(|i| {
            let f = 10.0 * (1000.0f64).powf(i as f64 / 399.0);
            (f, lin.current(f).norm())
        })
        .fold((0.0, 0.0), |a, b| if b.1 > a.1 { b } else { a })
}
