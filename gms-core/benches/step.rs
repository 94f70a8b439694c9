//! Host cost of one model step (criterion). The target's instruction counts come from
//! `cargo target-bench` (QEMU); these are the host figures beside them.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use gms_core::friction::presets;
use gms_core::{FrictionModel, Gms, LuGre, LugreParams, StaticMap, StaticParams};

const DT: f32 = 1e-4; // 10 kHz

fn bench(c: &mut Criterion) {
    let p = presets::table1();
    // Sticking: ±1 count (3.8 urad) dither in pre-sliding, every block elastic.
    let mut m = Gms::try_new(p).unwrap();
    let mut sign = 1.0f32;
    c.bench_function("gms6_step_sticking", |b| {
        b.iter(|| {
            sign = -sign;
            black_box(m.advance(black_box(sign * 3.8e-6), black_box(DT)))
        })
    });
    // Slipping: steady sliding at 0.5 rad/s, every block on the slip branch.
    let mut m = Gms::try_new(p).unwrap();
    m.advance(0.5, 1.0);
    c.bench_function("gms6_step_slipping", |b| {
        b.iter(|| black_box(m.advance(black_box(0.5 * DT), black_box(DT))))
    });
    let lp = LugreParams {
        stribeck: p.stribeck,
        negative: None,
        sigma0: 2.0,
        sigma1: 1e-3,
        sigma: p.sigma,
    };
    let mut l = LuGre::try_new(lp).unwrap();
    c.bench_function("lugre_step", |b| {
        b.iter(|| black_box(l.advance(black_box(0.5 * DT), black_box(DT))))
    });
    let sp = StaticParams {
        stribeck: p.stribeck,
        negative: None,
        sigma: p.sigma,
    };
    let mut s = StaticMap::try_new(sp).unwrap();
    c.bench_function("static_step", |b| {
        b.iter(|| black_box(s.advance(black_box(0.5 * DT), black_box(DT))))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
