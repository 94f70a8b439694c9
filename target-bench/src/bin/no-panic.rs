//! Link-time proof that the control path cannot panic on the target.
//!
//! This binary runs every function of the control path (the friction models, the controller's
//! position and current steps, the reference generator) on inputs the optimiser cannot see,
//! with `panic-never` as its panic handler: that handler refers to a symbol that does not
//! exist, so the release build links only if no panic (bounds check, overflow, unwrap, …)
//! is reachable from this code. `cargo build -p target-bench --bin no-panic --release
//! --target thumbv7em-none-eabihf` is the check; it runs in CI.
#![no_std]
#![no_main]

use core::hint::black_box;

use cortex_m_rt::entry;
use gms_core::controller::Controller;
use gms_core::reference::{Reference, Segment};
use gms_core::{
    FrictionModel, Gms, LuGre, LugreParams, StaticMap, StaticParams, presets, selftest,
};
use panic_never as _;

#[entry]
fn main() -> ! {
    let p = presets::table1();
    let (Ok(mut gms), Ok(mut guide), Ok(mut lugre), Ok(mut map), Ok(mut ctl)) = (
        Gms::try_new(black_box(p)),
        Gms::try_new(black_box(presets::guideway())),
        LuGre::try_new(black_box(LugreParams {
            stribeck: p.stribeck,
            negative: None,
            sigma0: 2.0,
            sigma1: 1e-3,
            sigma: p.sigma,
        })),
        StaticMap::try_new(black_box(StaticParams {
            stribeck: p.stribeck,
            negative: None,
            sigma: p.sigma,
        })),
        Controller::try_new(black_box(selftest::controller_params())),
    ) else {
        loop {
            cortex_m::asm::wfi();
        }
    };
    let segs = [
        Segment::Sine {
            amplitude: 0.05,
            freq: 1.0,
            cycles: 2.0,
        },
        Segment::Move {
            distance: 1e-3,
            vmax: 0.5,
            amax: 50.0,
            jmax: 1e4,
            dwell: 0.1,
        },
    ];
    let Ok(mut reference) = Reference::<8>::try_new(black_box(&segs), 3.8e-6, 0) else {
        loop {
            cortex_m::asm::wfi();
        }
    };
    loop {
        let dx: f32 = black_box(1e-6);
        let dt: f32 = black_box(1e-4);
        black_box(gms.advance(dx, dt));
        black_box(guide.advance(dx, dt));
        black_box(lugre.advance(dx, dt));
        black_box(map.advance(dx, dt));
        let r = reference.next(dt);
        black_box(ctl.position_step(black_box(12345i64), &r));
        black_box(ctl.current_step(black_box(0.01)));
        black_box(ctl.current_step(black_box(0.01)));
    }
}
