//! The parameter file ↔ the device's settings (`gms_bench::paramfile`), on the host.

use gms_bench::paramfile::{file_of, settings_with};
use gms_bench::settings::changes;
use gms_core::device::default_settings;
use gms_core::protocol::with_value_staged;

#[test]
fn a_dumped_file_loads_back_to_the_same_settings() {
    let base = default_settings();
    // A set unlike the defaults: four blocks, other gains and limits, another mode.
    let mut s = base;
    for (p, v) in [
        ("gms.blocks", "4"),
        ("gms.a1", "0.4"),
        ("gms.a2", "0.3"),
        ("gms.a3", "0.2"),
        ("gms.a4", "0.1"),
        ("pos.kp", "0.3125"),
        ("lim.pos_max", "2.5"),
        ("ff.gain", "0.87"),
        ("ff.mode", "static"),
        ("enc.counts_per_rev", "2000"),
        ("gms.c", "0.0123"),
    ] {
        s = with_value_staged(&s, p, v).unwrap_or_else(|e| panic!("{p} {v}: {}", e.reason));
    }
    s.validate().unwrap();
    let file = file_of(&s);
    assert_eq!(file.friction.blocks.as_ref().map(Vec::len), Some(4));
    // Through TOML text too, as `params dump` writes it and `params load` reads it.
    let text = file.to_toml();
    let again = gms_ident::paramfile::ParamFile::parse(&text, "dump.toml").unwrap();
    let back = settings_with(&again, &base).unwrap();
    assert!(changes(&s, &back).is_empty(), "{:?}", changes(&s, &back));
    assert_eq!(back.ff.actuator.blocks_used(), 4);
}

#[test]
fn what_the_device_cannot_hold_is_refused_whole() {
    let base = default_settings();
    let good = file_of(&base);
    let refused = |edit: &dyn Fn(&mut gms_ident::paramfile::ParamFile)| {
        let mut f = good.clone();
        edit(&mut f);
        settings_with(&f, &base).unwrap_err().to_string()
    };
    let e = refused(&|f| {
        f.friction.negative = Some(gms_ident::paramfile::NegativeSpec {
            fs: Some(2e-4),
            fc: Some(1e-4),
            vs: Some(0.2),
            delta: Some(1.0),
        })
    });
    assert!(e.contains("[friction.negative]"), "{e}");
    let e = refused(&|f| {
        let b = f.friction.blocks.as_ref().unwrap()[0];
        f.friction.blocks = Some(vec![b; 7]);
    });
    assert!(e.contains("1 to 6 blocks"), "{e}");
    let e = refused(&|f| {
        f.device
            .as_mut()
            .unwrap()
            .insert("pos.nonsense".into(), toml::Value::Float(1.0));
    });
    assert!(e.contains("pos.nonsense"), "{e}");
    let e = refused(&|f| {
        f.device
            .as_mut()
            .unwrap()
            .insert("pos.kp".into(), toml::Value::Float(-1.0));
    });
    assert!(e.contains("pos.kp"), "{e}");
    // Fc above Fs: every value in range, the whole set invalid.
    let e = refused(&|f| f.friction.fc = Some(f.friction.fs.unwrap() * 2.0));
    assert!(!e.is_empty());
}
