mod common;
use common::QUIET;
use gms_bench::{SlidingPlan, sliding};
use gms_ident::identify::fit_stribeck;
use hil_sim::device::LocalDevice;
use hil_sim::scenario::Scenario;

#[test]
fn probe() {
    let cfgs = std::env::var("PROBE").unwrap();
    for cfg in cfgs.split(';') {
        let f: Vec<f64> = cfg.split(',').map(|x| x.parse().unwrap()).collect();
        let text = format!(
            "{QUIET}\n[controller.rate]\npos_hz = {}\n[controller.pos]\nkp = {}\nki = {}\nkd = {}\nd_filter_hz = {}\n",
            f[0], f[1], f[2], f[3], f[4]
        );
        let sc = Scenario::parse(&text, "test").unwrap();
        let mut dev = LocalDevice::new(&sc).unwrap();
        let plan = SlidingPlan::log_spaced(0.02, 6.0, 10);
        let mut data = Vec::new();
        sliding(&mut dev, &plan, &mut data).unwrap();
        let mut out = String::new();
        for dir in [1.0, -1.0] {
            let (v, fr): (Vec<f64>, Vec<f64>) = data
                .iter()
                .filter(|(v, _)| v.signum() == dir)
                .map(|(v, f)| (v.abs(), f.abs()))
                .unzip();
            let fit = fit_stribeck(&v, &fr).unwrap();
            out += &format!(
                " fs {:+.1}% fc {:+.1}% vs {:+.1}% d {:+.1}% sg {:+.1}% |",
                (fit.fs / 220e-6 - 1.0) * 100.0,
                (fit.fc / 125e-6 - 1.0) * 100.0,
                (fit.vs / 0.2 - 1.0) * 100.0,
                (fit.delta / 0.9 - 1.0) * 100.0,
                (fit.sigma / 10.5e-6 - 1.0) * 100.0
            );
        }
        eprintln!("CFG {cfg}:{out}");
    }
}
