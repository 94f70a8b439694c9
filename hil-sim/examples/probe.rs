use gms_core::control::controller::FfMode;
use hil_sim::scenario::Scenario;
fn main() {
    let sc = Scenario::default();
    for mode in [FfMode::None, FfMode::Static, FfMode::Gms] {
        let t0 = std::time::Instant::now();
        let r = hil_sim::sim::run(&sc, mode, 1).unwrap();
        let e = r.energy;
        let bal = e.input - (e.copper + e.magnetic + e.friction + e.kinetic);
        let mech = e.converted - (e.friction + e.kinetic);
        println!(
            "{mode:?} {:.2}s {:?}",
            t0.elapsed().as_secs_f64(),
            r.metrics
        );
        println!(
            "   energy in {:.4e} cu {:.4e} conv {:.4e} fric {:.4e} ke {:.2e} bal {:.2e} mech-bal {:.2e}",
            e.input,
            e.copper,
            e.converted,
            e.friction,
            e.kinetic,
            bal / e.input,
            mech / e.converted
        );
    }
}
