//! The parameters' table, in one place: each parameter's id, path, unit, range, kind and field
//! in the settings, one row each ([`for_each_param!`]). It is a leaf, below the models and the
//! protocol: the rows are tokens, expanded where the settings' type is known. Here they make
//! [`ParamId`] and [`SPECS`]; the protocol makes its table (`protocol::PARAMS`: reading and
//! setting each field) from them, and `ControllerParams::validate` its range checks, so no
//! path, unit, range or field is written twice.

/// What a parameter is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A number within its range.
    Number,
    /// The friction feedforward's mode, set by name (`none`, `static`, `gms`, `gms-adaptive`).
    Mode,
    /// An on-line estimate: read-only.
    Estimate,
}

/// A parameter's name, unit, range and kind.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spec {
    /// The path, e.g. `pos.kp`.
    pub path: &'static str,
    /// The unit, e.g. `N·m/rad` (`-` for none).
    pub unit: &'static str,
    /// Smallest allowed value (a mode: its lowest code).
    pub min: f32,
    /// Largest allowed value (a mode: its highest code).
    pub max: f32,
    /// Only whole numbers (a count).
    pub integer: bool,
    /// What it is.
    pub kind: Kind,
}

/// Calls the macro `$then!` with every parameter's row, in the protocol's `list` order:
///
/// `Id "path" "unit" [min, max] real|int KIND |s| FIELD;`
///
/// - `Id`: the [`ParamId`] variant;
/// - `real` or `int`: only whole numbers for `int` (a count);
/// - `KIND`: `checked` (a number that `ControllerParams::validate` holds to its range),
///   `own` (a number checked by its own part: the directions, the adaptation, the GMS
///   blocks), `blocks` (the GMS block count: setting it clears the blocks past it), `mode`
///   (the feedforward's mode) or `estimate` (read-only);
/// - `FIELD`: the settings' field, `s` the settings (a unit `()` for an estimate).
///
/// A parameter is added here, and in the settings' type; nowhere else.
#[macro_export]
#[doc(hidden)]
macro_rules! for_each_param {
    ($then:ident) => {
        $then! {
            RatePosHz "rate.pos_hz" "Hz" [100.0, 50_000.0] real checked |s| s.pos_rate_hz;
            RateCurHz "rate.cur_hz" "Hz" [100.0, 100_000.0] real checked |s| s.cur_rate_hz;
            PosKp "pos.kp" "N·m/rad" [0.0, 1e3] real checked |s| s.pid.kp;
            PosKi "pos.ki" "N·m/(rad·s)" [0.0, 1e6] real checked |s| s.pid.ki;
            PosKd "pos.kd" "N·m·s/rad" [0.0, 1e3] real checked |s| s.pid.kd;
            PosDFilterHz "pos.d_filter_hz" "Hz" [1.0, 1e5] real checked |s| s.pid.d_filter_hz;
            PosILimit "pos.i_limit" "N·m" [0.0, 1e3] real checked |s| s.pid.i_limit;
            PosKiFric "pos.ki_fric" "-" [0.0, 1.0] real checked |s| s.pid.ki_fric;
            FiltNotch1FHz "filt.notch1.f_hz" "Hz" [0.0, 50_000.0] real checked |s| s.shaping.notch[0].f_hz;
            FiltNotch1Q "filt.notch1.q" "-" [0.1, 50.0] real checked |s| s.shaping.notch[0].q;
            FiltNotch1DepthDb "filt.notch1.depth_db" "dB" [0.0, 60.0] real checked |s| s.shaping.notch[0].depth_db;
            FiltNotch2FHz "filt.notch2.f_hz" "Hz" [0.0, 50_000.0] real checked |s| s.shaping.notch[1].f_hz;
            FiltNotch2Q "filt.notch2.q" "-" [0.1, 50.0] real checked |s| s.shaping.notch[1].q;
            FiltNotch2DepthDb "filt.notch2.depth_db" "dB" [0.0, 60.0] real checked |s| s.shaping.notch[1].depth_db;
            FiltLpFHz "filt.lp.f_hz" "Hz" [0.0, 50_000.0] real checked |s| s.shaping.lp_hz;
            CurKp "cur.kp" "V/A" [0.0, 1e4] real checked |s| s.current.kp;
            CurKi "cur.ki" "V/(A·s)" [0.0, 1e8] real checked |s| s.current.ki;
            MotorKM "motor.k_m" "N·m/A" [1e-6, 10.0] real checked |s| s.motor.k_m;
            MotorR "motor.r" "ohm" [0.0, 1e4] real checked |s| s.motor.r;
            MotorKE "motor.k_e" "V·s/rad" [0.0, 10.0] real checked |s| s.motor.k_e;
            LimIMax "lim.i_max" "A" [1e-6, 100.0] real checked |s| s.i_max;
            LimVSupply "lim.v_supply" "V" [0.1, 1e3] real checked |s| s.v_supply;
            LimPosMin "lim.pos_min" "rad" [-1e5, 1e5] real checked |s| s.pos_min;
            LimPosMax "lim.pos_max" "rad" [-1e5, 1e5] real checked |s| s.pos_max;
            DriveDeadTime "drive.dead_time" "s" [0.0, 5e-6] real checked |s| s.dead_time;
            EncDir "enc.dir" "-" [-1.0, 1.0] real own |s| s.enc_dir;
            EncCountsPerRev "enc.counts_per_rev" "count/rev" [4.0, 1e10] real checked |s| s.counts_per_rev;
            SenseDir "sense.dir" "-" [-1.0, 1.0] real own |s| s.sense_dir;
            SenseVPerA "sense.v_per_a" "V/A" [1e-3, 1e3] real checked |s| s.sense_v_per_a;
            FfMode "ff.mode" "-" [0.0, 3.0] int mode |s| s.ff.mode;
            FfGain "ff.gain" "-" [0.0, 2.0] real checked |s| s.ff.gain;
            FfInertia "ff.inertia" "kg·m^2" [0.0, 1.0] real checked |s| s.motor.inertia;
            FfStaticBand "ff.static_band" "rad/s" [0.0, 1e3] real checked |s| s.ff.static_band;
            FfAdaptGain "ff.adapt.gain" "1/s" [0.0, 1e4] real own |s| s.ff.adapt.gain;
            FfAdaptMin "ff.adapt.min" "-" [0.0, 10.0] real own |s| s.ff.adapt.min;
            FfAdaptMax "ff.adapt.max" "-" [0.0, 10.0] real own |s| s.ff.adapt.max;
            FfAdaptDeadzone "ff.adapt.deadzone" "N·m" [0.0, 1e3] real own |s| s.ff.adapt.deadzone;
            FfAdaptVmin "ff.adapt.vmin" "rad/s" [0.0, 1e4] real own |s| s.ff.adapt.v_min;
            FfAdaptScale "ff.adapt.scale" "-" [0.0, 10.0] real estimate |s| ();
            MapEnable "map.enable" "-" [0.0, 1.0] int checked |s| s.map.enable;
            MapPeriod "map.period" "rad" [1e-3, 1e4] real checked |s| s.map.period;
            MapBins "map.bins" "-" [8.0, 512.0] int checked |s| s.map.bins;
            MapOrigin "map.origin" "rad" [-1e4, 1e4] real checked |s| s.map.origin;
            GmsFs "gms.fs" "N·m" [0.0, 10.0] real checked |s| s.ff.actuator.stribeck.fs;
            GmsFc "gms.fc" "N·m" [0.0, 10.0] real checked |s| s.ff.actuator.stribeck.fc;
            GmsVs "gms.vs" "rad/s" [1e-9, 1e4] real checked |s| s.ff.actuator.stribeck.vs;
            GmsDelta "gms.delta" "-" [0.01, 10.0] real checked |s| s.ff.actuator.stribeck.delta;
            GmsSigma "gms.sigma" "N·m·s/rad" [0.0, 10.0] real checked |s| s.ff.actuator.sigma;
            GmsC "gms.c" "N·m/s" [1e-12, 1e6] real checked |s| s.ff.actuator.c;
            GmsBlocks "gms.blocks" "-" [1.0, 6.0] int blocks |s| s.ff.actuator;
            GmsK1 "gms.k1" "N·m/rad" [0.0, 1e9] real own |s| s.ff.actuator.blocks[0].k;
            GmsK2 "gms.k2" "N·m/rad" [0.0, 1e9] real own |s| s.ff.actuator.blocks[1].k;
            GmsK3 "gms.k3" "N·m/rad" [0.0, 1e9] real own |s| s.ff.actuator.blocks[2].k;
            GmsK4 "gms.k4" "N·m/rad" [0.0, 1e9] real own |s| s.ff.actuator.blocks[3].k;
            GmsK5 "gms.k5" "N·m/rad" [0.0, 1e9] real own |s| s.ff.actuator.blocks[4].k;
            GmsK6 "gms.k6" "N·m/rad" [0.0, 1e9] real own |s| s.ff.actuator.blocks[5].k;
            GmsA1 "gms.a1" "-" [0.0, 1.0] real own |s| s.ff.actuator.blocks[0].alpha;
            GmsA2 "gms.a2" "-" [0.0, 1.0] real own |s| s.ff.actuator.blocks[1].alpha;
            GmsA3 "gms.a3" "-" [0.0, 1.0] real own |s| s.ff.actuator.blocks[2].alpha;
            GmsA4 "gms.a4" "-" [0.0, 1.0] real own |s| s.ff.actuator.blocks[3].alpha;
            GmsA5 "gms.a5" "-" [0.0, 1.0] real own |s| s.ff.actuator.blocks[4].alpha;
            GmsA6 "gms.a6" "-" [0.0, 1.0] real own |s| s.ff.actuator.blocks[5].alpha;
        }
    };
}
pub use for_each_param;

/// [`ParamId`] and [`SPECS`] from the rows.
macro_rules! ids_and_specs {
    ($($id:ident $path:literal $unit:literal [$min:expr, $max:expr] $num:ident $kind:ident
       |$s:ident| $field:expr;)*) => {
        /// A parameter, typed: what a host names instead of its path (`ParamId::PosKp.path()`
        /// is `pos.kp`), in `list` order.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        #[repr(u8)]
        pub enum ParamId {
            $(
                #[doc = concat!("`", $path, "` \\[", $unit, "\\]")]
                $id,
            )*
        }

        impl ParamId {
            /// Every parameter, in `list` order.
            pub const ALL: &'static [ParamId] = &[$(ParamId::$id),*];

            /// The protocol's path (`pos.kp`).
            pub const fn path(self) -> &'static str {
                SPECS[self as usize].path
            }

            /// Its unit, range and kind.
            pub const fn spec(self) -> Spec {
                SPECS[self as usize]
            }

            /// Its range `(min, max)`.
            pub const fn range(self) -> (f32, f32) {
                (SPECS[self as usize].min, SPECS[self as usize].max)
            }

            /// The parameter with this path, if any.
            pub fn from_path(path: &str) -> Option<ParamId> {
                ParamId::ALL.iter().copied().find(|p| p.path() == path)
            }
        }

        impl core::fmt::Display for ParamId {
            /// The path.
            fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                f.write_str(self.path())
            }
        }

        /// Every parameter's spec, in `list` order (indexed by [`ParamId`]).
        pub const SPECS: &[Spec] = &[$(
            Spec {
                path: $path,
                unit: $unit,
                min: $min,
                max: $max,
                integer: ids_and_specs!(@int $num),
                kind: ids_and_specs!(@kind $kind),
            },
        )*];
    };
    (@int int) => { true };
    (@int real) => { false };
    (@kind mode) => { Kind::Mode };
    (@kind estimate) => { Kind::Estimate };
    (@kind $other:ident) => { Kind::Number };
}

for_each_param!(ids_and_specs);
