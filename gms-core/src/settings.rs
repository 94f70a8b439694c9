//! The parameters' names, units and ranges: a leaf table, below the models and the protocol.
//! The models validate against it (`ControllerParams::validate`, the adaptation's ranges), and
//! the protocol's parameter table (`protocol::PARAMS`: each path's field in the settings) takes
//! its units and ranges from it, so no range is written twice and neither imports the other.

/// A numeric parameter's name, unit and range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spec {
    /// The path, e.g. `pos.kp`.
    pub path: &'static str,
    /// The unit, e.g. `N·m/rad` (`-` for none).
    pub unit: &'static str,
    /// Smallest allowed value.
    pub min: f32,
    /// Largest allowed value.
    pub max: f32,
    /// Only whole numbers (a count).
    pub integer: bool,
}

/// Every numeric parameter, in the protocol's `list` order.
pub const SPECS: &[Spec] = &[
    Spec {
        path: "rate.pos_hz",
        unit: "Hz",
        min: 100.0,
        max: 50_000.0,
        integer: false,
    },
    Spec {
        path: "rate.cur_hz",
        unit: "Hz",
        min: 100.0,
        max: 100_000.0,
        integer: false,
    },
    Spec {
        path: "pos.kp",
        unit: "N·m/rad",
        min: 0.0,
        max: 1e3,
        integer: false,
    },
    Spec {
        path: "pos.ki",
        unit: "N·m/(rad·s)",
        min: 0.0,
        max: 1e6,
        integer: false,
    },
    Spec {
        path: "pos.kd",
        unit: "N·m·s/rad",
        min: 0.0,
        max: 1e3,
        integer: false,
    },
    Spec {
        path: "pos.d_filter_hz",
        unit: "Hz",
        min: 1.0,
        max: 1e5,
        integer: false,
    },
    Spec {
        path: "pos.i_limit",
        unit: "N·m",
        min: 0.0,
        max: 1e3,
        integer: false,
    },
    Spec {
        path: "pos.ki_fric",
        unit: "-",
        min: 0.0,
        max: 1.0,
        integer: false,
    },
    Spec {
        path: "filt.notch1.f_hz",
        unit: "Hz",
        min: 0.0,
        max: 50_000.0,
        integer: false,
    },
    Spec {
        path: "filt.notch1.q",
        unit: "-",
        min: 0.1,
        max: 50.0,
        integer: false,
    },
    Spec {
        path: "filt.notch1.depth_db",
        unit: "dB",
        min: 0.0,
        max: 60.0,
        integer: false,
    },
    Spec {
        path: "filt.notch2.f_hz",
        unit: "Hz",
        min: 0.0,
        max: 50_000.0,
        integer: false,
    },
    Spec {
        path: "filt.notch2.q",
        unit: "-",
        min: 0.1,
        max: 50.0,
        integer: false,
    },
    Spec {
        path: "filt.notch2.depth_db",
        unit: "dB",
        min: 0.0,
        max: 60.0,
        integer: false,
    },
    Spec {
        path: "filt.lp.f_hz",
        unit: "Hz",
        min: 0.0,
        max: 50_000.0,
        integer: false,
    },
    Spec {
        path: "cur.kp",
        unit: "V/A",
        min: 0.0,
        max: 1e4,
        integer: false,
    },
    Spec {
        path: "cur.ki",
        unit: "V/(A·s)",
        min: 0.0,
        max: 1e8,
        integer: false,
    },
    Spec {
        path: "motor.k_m",
        unit: "N·m/A",
        min: 1e-6,
        max: 10.0,
        integer: false,
    },
    Spec {
        path: "motor.r",
        unit: "ohm",
        min: 0.0,
        max: 1e4,
        integer: false,
    },
    Spec {
        path: "motor.k_e",
        unit: "V·s/rad",
        min: 0.0,
        max: 10.0,
        integer: false,
    },
    Spec {
        path: "lim.i_max",
        unit: "A",
        min: 1e-6,
        max: 100.0,
        integer: false,
    },
    Spec {
        path: "lim.v_supply",
        unit: "V",
        min: 0.1,
        max: 1e3,
        integer: false,
    },
    Spec {
        path: "lim.pos_min",
        unit: "rad",
        min: -1e5,
        max: 1e5,
        integer: false,
    },
    Spec {
        path: "lim.pos_max",
        unit: "rad",
        min: -1e5,
        max: 1e5,
        integer: false,
    },
    Spec {
        path: "enc.dir",
        unit: "-",
        min: -1.0,
        max: 1.0,
        integer: false,
    },
    Spec {
        path: "enc.counts_per_rev",
        unit: "count/rev",
        min: 4.0,
        max: 1e10,
        integer: false,
    },
    Spec {
        path: "sense.dir",
        unit: "-",
        min: -1.0,
        max: 1.0,
        integer: false,
    },
    Spec {
        path: "sense.v_per_a",
        unit: "V/A",
        min: 1e-3,
        max: 1e3,
        integer: false,
    },
    Spec {
        path: "ff.gain",
        unit: "-",
        min: 0.0,
        max: 2.0,
        integer: false,
    },
    Spec {
        path: "ff.inertia",
        unit: "kg·m^2",
        min: 0.0,
        max: 1.0,
        integer: false,
    },
    Spec {
        path: "ff.static_band",
        unit: "rad/s",
        min: 0.0,
        max: 1e3,
        integer: false,
    },
    Spec {
        path: "ff.adapt.gain",
        unit: "1/s",
        min: 0.0,
        max: 1e4,
        integer: false,
    },
    Spec {
        path: "ff.adapt.min",
        unit: "-",
        min: 0.0,
        max: 10.0,
        integer: false,
    },
    Spec {
        path: "ff.adapt.max",
        unit: "-",
        min: 0.0,
        max: 10.0,
        integer: false,
    },
    Spec {
        path: "ff.adapt.deadzone",
        unit: "N·m",
        min: 0.0,
        max: 1e3,
        integer: false,
    },
    Spec {
        path: "ff.adapt.vmin",
        unit: "rad/s",
        min: 0.0,
        max: 1e4,
        integer: false,
    },
    Spec {
        path: "map.enable",
        unit: "-",
        min: 0.0,
        max: 1.0,
        integer: true,
    },
    Spec {
        path: "map.period",
        unit: "rad",
        min: 1e-3,
        max: 1e4,
        integer: false,
    },
    Spec {
        path: "map.bins",
        unit: "-",
        min: 8.0,
        max: 512.0,
        integer: true,
    },
    Spec {
        path: "map.origin",
        unit: "rad",
        min: -1e4,
        max: 1e4,
        integer: false,
    },
    Spec {
        path: "gms.fs",
        unit: "N·m",
        min: 0.0,
        max: 10.0,
        integer: false,
    },
    Spec {
        path: "gms.fc",
        unit: "N·m",
        min: 0.0,
        max: 10.0,
        integer: false,
    },
    Spec {
        path: "gms.vs",
        unit: "rad/s",
        min: 1e-9,
        max: 1e4,
        integer: false,
    },
    Spec {
        path: "gms.delta",
        unit: "-",
        min: 0.01,
        max: 10.0,
        integer: false,
    },
    Spec {
        path: "gms.sigma",
        unit: "N·m·s/rad",
        min: 0.0,
        max: 10.0,
        integer: false,
    },
    Spec {
        path: "gms.c",
        unit: "N·m/s",
        min: 1e-12,
        max: 1e6,
        integer: false,
    },
    Spec {
        path: "gms.blocks",
        unit: "-",
        min: 1.0,
        max: 6.0,
        integer: true,
    },
    Spec {
        path: "gms.k1",
        unit: "N·m/rad",
        min: 0.0,
        max: 1e9,
        integer: false,
    },
    Spec {
        path: "gms.k2",
        unit: "N·m/rad",
        min: 0.0,
        max: 1e9,
        integer: false,
    },
    Spec {
        path: "gms.k3",
        unit: "N·m/rad",
        min: 0.0,
        max: 1e9,
        integer: false,
    },
    Spec {
        path: "gms.k4",
        unit: "N·m/rad",
        min: 0.0,
        max: 1e9,
        integer: false,
    },
    Spec {
        path: "gms.k5",
        unit: "N·m/rad",
        min: 0.0,
        max: 1e9,
        integer: false,
    },
    Spec {
        path: "gms.k6",
        unit: "N·m/rad",
        min: 0.0,
        max: 1e9,
        integer: false,
    },
    Spec {
        path: "gms.a1",
        unit: "-",
        min: 0.0,
        max: 1.0,
        integer: false,
    },
    Spec {
        path: "gms.a2",
        unit: "-",
        min: 0.0,
        max: 1.0,
        integer: false,
    },
    Spec {
        path: "gms.a3",
        unit: "-",
        min: 0.0,
        max: 1.0,
        integer: false,
    },
    Spec {
        path: "gms.a4",
        unit: "-",
        min: 0.0,
        max: 1.0,
        integer: false,
    },
    Spec {
        path: "gms.a5",
        unit: "-",
        min: 0.0,
        max: 1.0,
        integer: false,
    },
    Spec {
        path: "gms.a6",
        unit: "-",
        min: 0.0,
        max: 1.0,
        integer: false,
    },
];

const fn str_eq(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

/// The numeric parameter `path`'s spec, for use in constant context (`const { spec("pos.kp") }`):
/// an unknown path fails the build.
pub const fn spec(path: &str) -> Spec {
    let mut i = 0;
    while i < SPECS.len() {
        if str_eq(SPECS[i].path, path) {
            return SPECS[i];
        }
        i += 1;
    }
    panic!("not a numeric parameter of the table")
}

/// The range `(min, max)` of the numeric parameter `path`, for use in constant context only
/// (`const { range("pos.kp") }`): an unknown path fails the build.
pub const fn range(path: &str) -> (f32, f32) {
    let s = spec(path);
    (s.min, s.max)
}
