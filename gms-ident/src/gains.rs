//! Loop gains from a measured motor: the current loop's PI from a crossover, and the
//! position loop's PID with the derivative gain chosen for the margins of the linear model
//! over the plant variations commissioning must hold (kp lowered until they meet the floor),
//! between the friction's lower bound and the loop's stability limit (docs/commissioning.md).
//!
//! The rules reproduce the device's defaults for the default motor (R 10 Ω, L 0.24 mH,
//! J 6e-8 kg·m², the current loop at 40 kHz and the position loop at 20 kHz, the derivative
//! filter at 0.45 of the position rate): cur.kp 10.85, cur.ki 1.98e4, pos.kp 0.49, pos.ki
//! 700, pos.kd 2.45e-4, pos.d_filter_hz 9000.

use gms_core::control::controller::{ControllerParams, FfMode};
use gms_core::settings::ParamId;

/// The current loop's gain margin against its own delay \[-\]: its loop gain through the
/// winding is this at the frequency where the delay and the winding turn its phase by 180°
/// (0.63: 4 dB). A trade: at 6 dB (0.5) the position loop the rule then allows (kp 0.42 on
/// the default motor) leaves the demo's reversal peak at 8.3 counts; at 4 dB (kp 0.49) 7.3;
/// at 3 dB (kp 0.54) 6.5 (`hil-sim compare --runs 20`, GMS).
pub const CURRENT_GAIN_MARGIN: f64 = 0.63;

/// The current loop's reference crossover as a fraction of its rate \[-\]: the position
/// loop's natural frequency is a fraction of it ([`POS_NATURAL_FRACTION`]; 2 kHz at the
/// default 40 kHz).
pub const CURRENT_BW_FRACTION: f64 = 0.05;

/// The position loop's natural frequency as a fraction of the current loop's crossover
/// \[-\]: 0.2516 (503 Hz under 2 kHz: kp 0.6 on 6e-8 kg·m²), where the rule starts; it
/// lowers kp from there until the margins over the plant variations meet the floor.
pub const POS_NATURAL_FRACTION: f64 = 0.2516;

/// The integral's corner below the position loop's natural frequency \[-\]: ki = kp ω_n / 2.
pub const POS_INTEGRAL_DIVISOR: f64 = 2.0;

/// The derivative filter's corner over the position loop's natural frequency \[-\], as a cap
/// on the axis's own corner: 24 (the default tune's 9 kHz, 0.45 of the position rate, is
/// under 24 × its 455 Hz, so it stays). A loop the encoder's count holds down (a coarse
/// encoder: the natural frequency low) gets a lower corner, so that each count's step reaches
/// the motor smaller and over more periods: on a 2000 counts/rev gear motor (85 Hz) 2 kHz,
/// where with an 8 kHz corner its sliding friction read 15 % off (the fit's Fc; the points
/// scatter ±20 % either way).
pub const D_FILTER_NATURAL: f64 = 24.0;

/// The current loop's PI at `cur_hz` \[Hz\] on a winding of `r` \[ohm\] and `l` \[H\]:
/// `(kp [V/A], ki [V/(A·s)])`. The device feeds the resistance's drop forward (`motor.r` × the
/// command), so the command reaches the winding at its own corner R / L (6.6 kHz on the
/// default motor) and the PI's feedback corrects it: kp is as high as the loop's delay (1.5
/// periods: the voltage computed from a sample is applied over the next period) allows with
/// [`CURRENT_GAIN_MARGIN`] — at ω₁₈₀, where ω τ + atan(ω L / R) = π, the loop gain
/// kp / |j ω₁₈₀ L + R| is 0.63 — and the integral's corner five octaves below ω₁₈₀. On the
/// default motor at 40 kHz: ω₁₈₀ 2π × 9.3 kHz, kp 10.85, ki 1.98e4. (A PI with its zero on the
/// winding's pole, (ω L, ω R), beside the feedforward peaks +5 dB near 2.5 kHz.)
pub fn current_pi(r: f64, l: f64, cur_hz: f64) -> (f64, f64) {
    let tau = 1.5 / cur_hz;
    let phase = |w: f64| w * tau + (w * l / r).atan();
    let (mut lo, mut hi) = (0.0, std::f64::consts::PI / tau);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if phase(mid) < std::f64::consts::PI {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let w = lo;
    let kp = CURRENT_GAIN_MARGIN * (r * r + (w * l) * (w * l)).sqrt();
    (kp, kp * w / 32.0)
}

/// The measuring loop's damping ratio \[-\]: the position loop the friction is measured with
/// ([`measuring_loop`]) is overdamped this much, a velocity loop (the derivative gain) with a
/// weak position correction.
pub const MEASURE_DAMPING: f64 = 1.5;

/// The position loop's gains the sliding friction is measured with (`pos.kd` kept).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuringLoop {
    /// `pos.kp` [N·m/rad].
    pub kp: f64,
    /// `pos.ki` [N·m/(rad·s)].
    pub ki: f64,
    /// `pos.d_filter_hz` \[Hz\].
    pub d_filter_hz: f64,
}

/// The loop the friction is measured with, from the position loop's `kp` [N·m/rad], `kd`
/// [N·m·s/rad] (kept: it holds the Stribeck curve's negative damping) and derivative filter
/// `d_filter_hz` \[Hz\] on an inertia `inertia` [kg·m²], the position loop at `pos_hz` \[Hz\];
/// `None` when the figures are not finite and positive, or when the loop is not one to build
/// on: damped below half of critical (kd < sqrt(kp J), as a coarse encoder's count-limited kd
/// leaves it), where the derivative gain alone would be a velocity loop too slow to hold the
/// axis against the friction's model error. Then the friction is measured in the loop as it
/// is.
///
/// At constant speed a tracking loop answers the encoder's quantisation: the count rate beats
/// against the sampling at frequencies up to the Nyquist limit, the loop follows the beats,
/// and the speed ripples. Averaged over the Stribeck curve, convex below Vs, the ripple reads
/// the friction high at the lowest speeds — on the paper's encoder +3 to +5 % between Vs/10
/// and Vs/2 with the default 20 kHz loop (kp 0.7), and the fitted δ +12 %. This loop is a
/// velocity loop of bandwidth ω_d = kd / J (the derivative gain alone), its derivative
/// filtered at that bandwidth (the beats above it do not reach the motor), and a position
/// correction weak enough to leave it overdamped, damping ratio [`MEASURE_DAMPING`]: ω_n =
/// ω_d / (2 ζ), kp = J ω_n², ki = kp ω_n / 4 (the integral's corner two octaves below ω_n:
/// softer than [`position_gains`]' octave). It only softens: kp and the filter's corner are at most the loop's,
/// and the corner below 0.45 of the position rate.
pub fn measuring_loop(
    kp: f64,
    kd: f64,
    d_filter_hz: f64,
    inertia: f64,
    pos_hz: f64,
) -> Option<MeasuringLoop> {
    let ok = |v: f64| v.is_finite() && v > 0.0;
    if !(ok(kp) && ok(kd) && ok(d_filter_hz) && ok(inertia) && ok(pos_hz)) {
        return None;
    }
    if kd < (kp * inertia).sqrt() {
        return None;
    }
    let w_d = kd / inertia;
    let w_n = w_d / (2.0 * MEASURE_DAMPING);
    let kp = (inertia * w_n * w_n).min(kp);
    let w_n = (kp / inertia).sqrt();
    Some(MeasuringLoop {
        kp,
        ki: kp * w_n / 4.0,
        d_filter_hz: (w_d / (2.0 * std::f64::consts::PI))
            .min(d_filter_hz)
            .min(0.45 * pos_hz),
    })
}

/// The friction's Stribeck curve as the compensator holds it (SI).
#[derive(Debug, Clone, Copy)]
pub struct SlidingCurve {
    /// Static friction [N·m].
    pub fs: f64,
    /// Coulomb friction [N·m].
    pub fc: f64,
    /// Stribeck velocity \[rad/s\].
    pub vs: f64,
    /// Stribeck shape exponent \[-\].
    pub delta: f64,
    /// Viscous coefficient [N·m·s/rad].
    pub sigma: f64,
}

impl SlidingCurve {
    /// The paper's Table 1 in SI (docs/design.md#reading-table-1): the device's default
    /// compensator.
    pub const TABLE1: SlidingCurve = SlidingCurve {
        fs: 220e-6,
        fc: 125e-6,
        vs: 0.2,
        delta: 0.9,
        sigma: 10.5e-6,
    };

    /// The friction's negative damping the derivative gain must exceed [N·m·s/rad]: the
    /// Stribeck curve's slope at its Stribeck velocity, −s'(Vs) = (Fs − Fc) δ / (e Vs), less
    /// the viscous coefficient. (Below Vs the curve is steeper — infinitely so at 0 for
    /// δ < 1 — but there the axis is mostly in pre-sliding: the blocks stick and the friction
    /// acts as a spring, not as a negative damper.)
    pub fn negative_slope(&self) -> f64 {
        (self.fs - self.fc) * self.delta / (std::f64::consts::E * self.vs) - self.sigma
    }
}

/// What the position loop is tuned for: the measured motor and the device's loops.
#[derive(Debug, Clone, Copy)]
pub struct Axis {
    /// Winding resistance \[ohm\].
    pub r: f64,
    /// Winding inductance \[H\].
    pub l: f64,
    /// Back-EMF constant = torque constant [V·s/rad = N·m/A].
    pub k_m: f64,
    /// Reflected inertia [kg·m²].
    pub inertia: f64,
    /// The current loop's PI (`cur.kp` [V/A], `cur.ki` [V/(A·s)]).
    pub cur_pi: (f64, f64),
    /// Current-loop rate \[Hz\].
    pub cur_hz: f64,
    /// Position-loop rate \[Hz\].
    pub pos_hz: f64,
    /// The derivative's filter corner (`pos.d_filter_hz`) \[Hz\].
    pub d_filter_hz: f64,
    /// Supply voltage \[V\].
    pub v_supply: f64,
    /// The friction's initial pre-sliding stiffness (the sum of the blocks' k) [N·m/rad]: at
    /// rest the friction is a spring to the frame.
    pub k_presliding: f64,
    /// The encoder's resolution \[rad/count\]: one count of error must not ask for more than
    /// a share of the current limit ([`COUNT_SHARE`]).
    pub rad_per_count: f64,
    /// The current limit (`lim.i_max`) \[A\].
    pub i_max: f64,
}

/// The share of the current limit one count of position error may ask for through `pos.kp`,
/// and a one-count step through the filtered derivative `pos.kd` \[-\]: on a coarse encoder
/// (a gear motor's 2000 counts/rev) the loop's own quantisation would otherwise swing the
/// current by amps per count and trip `over_current`; on the paper's 3.8 µrad it never
/// binds (a count asks 0.02 % of the limit at the default gains).
pub const COUNT_SHARE: (f64, f64) = (0.1, 0.25);

impl Axis {
    /// The default motor and loops — R 10 Ω, L 0.24 mH, k 6.6 mN·m/A, J 6e-8 kg·m², the
    /// current PI of [`current_pi`] at 40 kHz, the position loop at 20 kHz, the derivative
    /// filter's cap at 15 kHz (the rule's 24 × ω_n and 0.45 of the position rate bind
    /// first), 12 V, a 0.5 A limit — with Table 1's pre-sliding stiffness (1.2501 N·m/rad).
    pub fn default_motor() -> Axis {
        Axis {
            r: 10.0,
            l: 0.24e-3,
            k_m: 6.6e-3,
            inertia: 6e-8,
            cur_pi: current_pi(10.0, 0.24e-3, 40e3),
            cur_hz: 40e3,
            pos_hz: 20e3,
            d_filter_hz: 15000.0,
            v_supply: 12.0,
            k_presliding: 1.2501,
            rad_per_count: 3.8e-6,
            i_max: 0.5,
        }
    }

    /// The largest `pos.kp` whose answer to one count of error is [`COUNT_SHARE`]`.0` of the
    /// current limit [N·m/rad].
    pub fn kp_count_limit(&self) -> f64 {
        COUNT_SHARE.0 * self.k_m * self.i_max / self.rad_per_count
    }

    /// The largest `pos.kd` whose filtered derivative answers a one-count step with
    /// [`COUNT_SHARE`]`.1` of the current limit [N·m·s/rad]: the filter's first output after
    /// a step of one count is (1 − e^(−2π f_d T)) / T counts per second.
    pub fn kd_count_limit(&self) -> f64 {
        let t = 1.0 / self.pos_hz;
        let first = (1.0 - (-2.0 * std::f64::consts::PI * self.d_filter_hz * t).exp()) / t;
        COUNT_SHARE.1 * self.k_m * self.i_max / (self.rad_per_count * first)
    }
}

/// The position loop's gains and their margins.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionGains {
    /// `pos.kp` [N·m/rad]: J ω_n², ω_n = [`POS_NATURAL_FRACTION`] × the current bandwidth,
    /// or lower where the encoder's count limits it ([`Axis::kp_count_limit`]).
    pub kp: f64,
    /// `pos.ki` [N·m/(rad·s)]: kp ω_n / [`POS_INTEGRAL_DIVISOR`] (the integral's corner an
    /// octave below ω_n), halved where that alone leaves no kp over the floor.
    pub ki: f64,
    /// `pos.kd` [N·m·s/rad]: of a log-spaced set between 0.5 and 4 × J ω_n (above `kd_min`
    /// where that leaves room; below `kd_max` / 1.5 and [`Axis::kd_count_limit`]), the one
    /// whose least margin over [`VARIATIONS`] is the most over [`AIM`].
    pub kd: f64,
    /// `pos.d_filter_hz` \[Hz\]: [`D_FILTER_NATURAL`] × the natural frequency, at most the
    /// axis's (and 0.45 of its position rate).
    pub d_filter_hz: f64,
    /// The lower bound: the friction's negative damping [N·m·s/rad].
    pub kd_min: f64,
    /// The upper bound: where the loop (these kp, ki, the device's current loop, the winding
    /// and the inertia, simulated with the device's own controller) goes unstable
    /// [N·m·s/rad].
    pub kd_max: f64,
    /// Whether the encoder's count lowered kp or kd below the rule's.
    pub count_limited: bool,
    /// The linear model's margins of the loop with these gains on the axis as measured.
    pub nominal: LoopMargins,
    /// The least of them over the plant variations of [`VARIATIONS`].
    pub worst: LoopMargins,
}

/// A loop's margins at rest (the friction's pre-sliding spring in the loop) and sliding.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopMargins {
    /// At rest: phase margin \[deg\], gain margin \[dB\].
    pub rest: (f64, f64),
    /// Sliding: phase margin \[deg\], gain margin \[dB\].
    pub sliding: (f64, f64),
}

impl LoopMargins {
    /// The least of the four over the floor's \[-\]: 1 or more meets
    /// [`MIN_PHASE_MARGIN_DEG`] and [`MIN_GAIN_MARGIN_DB`] everywhere.
    pub fn over_floor(&self) -> f64 {
        self.score(MIN_PHASE_MARGIN_DEG, MIN_GAIN_MARGIN_DB)
    }

    /// The least of the phase margins over `pm` and the gain margins over `gm`.
    fn score(&self, pm: f64, gm: f64) -> f64 {
        let f = |v: f64, d: f64| if v.is_nan() { 0.0 } else { v / d };
        f(self.rest.0, pm)
            .min(f(self.rest.1, gm))
            .min(f(self.sliding.0, pm))
            .min(f(self.sliding.1, gm))
    }

    /// The least of each of `self` and `o`.
    fn least(&self, o: &LoopMargins) -> LoopMargins {
        let m = |a: f64, b: f64| if a.is_nan() || b < a { b } else { a };
        LoopMargins {
            rest: (m(self.rest.0, o.rest.0), m(self.rest.1, o.rest.1)),
            sliding: (
                m(self.sliding.0, o.sliding.0),
                m(self.sliding.1, o.sliding.1),
            ),
        }
    }
}

pub use crate::margins::{MIN_GAIN_MARGIN_DB, MIN_PHASE_MARGIN_DEG};

/// The plant variations the rule holds its margins over, as factors on what was measured:
/// the pre-sliding stiffness (×0.5, ×1, ×2: load, lubricant, temperature, a friction model
/// that is not the axis's) and the inertia (×0.8, ×1, ×1.2).
pub const VARIATIONS: ([f64; 3], [f64; 3]) = ([0.5, 1.0, 2.0], [0.8, 1.0, 1.2]);

/// The margins the rule aims at \[deg, dB\]: the derivative gain is chosen for the most of
/// them over [`VARIATIONS`].
pub const AIM: (f64, f64) = (45.0, 8.0);

/// How many times, at most, the rule lowers kp (×0.95) when the best derivative gain leaves
/// the worst variation under the floor.
pub const KP_STEPS_DOWN: usize = 24;

impl PositionGains {
    /// The device's parameters these set (SI).
    pub fn sets(&self) -> [(ParamId, f64); 4] {
        [
            (ParamId::PosKp, self.kp),
            (ParamId::PosKi, self.ki),
            (ParamId::PosKd, self.kd),
            (ParamId::PosDFilterHz, self.d_filter_hz),
        ]
    }

    /// kd over its lower bound \[-\] (below 1: the friction can drive a limit cycle).
    pub fn margin_low(&self) -> f64 {
        self.kd / self.kd_min
    }
    /// The stability limit over kd \[-\].
    pub fn margin_high(&self) -> f64 {
        self.kd_max / self.kd
    }
}

/// The position loop's gains for `axis` under the friction `s`; `None` when the axis's
/// figures cannot make a controller (not finite, not positive).
pub fn position_gains(axis: &Axis, s: &SlidingCurve) -> Option<PositionGains> {
    let w_cur = 2.0 * std::f64::consts::PI * CURRENT_BW_FRACTION * axis.cur_hz;
    let wn_rule = POS_NATURAL_FRACTION * w_cur;
    let kp_rule = axis.inertia * wn_rule * wn_rule;
    let mut kp = kp_rule.min(axis.kp_count_limit());
    if !(kp.is_finite() && kp > 0.0) {
        return None;
    }
    let kd_min = s.negative_slope().max(0.0);
    let kp0 = kp;
    let mut best: Option<PositionGains> = None;
    // The rule's ki first; only where no kp meets the floor with it, half of it as well.
    'search: for halve in [false, true] {
        kp = kp0;
        for _ in 0..=KP_STEPS_DOWN {
            // No loop at this kp that the model finds stable even with little kd: a lower one.
            let Some(g) = gains_at(axis, s, kp, kd_min, halve) else {
                kp *= 0.95;
                continue;
            };
            let done = g.worst.over_floor() >= 1.0;
            if best
                .as_ref()
                .is_none_or(|b| g.worst.over_floor() > b.worst.over_floor())
            {
                best = Some(g);
            }
            if done {
                break 'search;
            }
            kp *= 0.95;
        }
    }
    let by_count = kp_rule > axis.kp_count_limit();
    best.map(|g| PositionGains {
        count_limited: g.count_limited || by_count,
        ..g
    })
}

/// The gains at `kp`: ki from the natural frequency, the filter's corner, the stability
/// limit, and kd the one of a log-spaced set between 0.5 and 4 × J ω_n (above `kd_min`, the
/// friction's negative damping, where that leaves room; below the stability limit / 1.5 and
/// the encoder's count limit) whose least margin over [`VARIATIONS`] is the most over
/// [`AIM`].
fn gains_at(
    axis: &Axis,
    s: &SlidingCurve,
    kp: f64,
    kd_min: f64,
    halve_ki: bool,
) -> Option<PositionGains> {
    let wn = (kp / axis.inertia).sqrt();
    let ki = kp * wn / POS_INTEGRAL_DIVISOR;
    // The derivative's filter: at most D_FILTER_NATURAL × the natural frequency (and the
    // axis's, and 0.45 of the position rate); the stability limit and the count's limit are
    // those of the loop with it.
    let d_filter_hz = (D_FILTER_NATURAL * wn / (2.0 * std::f64::consts::PI))
        .min(axis.d_filter_hz)
        .min(0.45 * axis.pos_hz);
    let axis = &Axis {
        d_filter_hz,
        ..*axis
    };
    // The stability limit: bisection on a log scale between a kd surely stable with these
    // kp, ki (critically damped at ω_n is 2 J ω_n; far below the limit) and 100 times it.
    let (mut lo, mut hi) = (0.5 * axis.inertia * wn, 200.0 * axis.inertia * wn);
    if !stable(axis, s.sigma, kp, ki, lo)? {
        return None;
    }
    // Still stable at 100 times the critical damping: the limit is taken there.
    let beyond = stable(axis, s.sigma, kp, ki, hi)?;
    for _ in 0..if beyond { 0 } else { 30 } {
        let mid = (lo * hi).sqrt();
        if stable(axis, s.sigma, kp, ki, mid)? {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let kd_max = if beyond { hi } else { lo };
    let top = (kd_max / 1.5).min(axis.kd_count_limit());
    let jw = axis.inertia * wn;
    let (from, to) = (
        (0.5 * jw).max(kd_min.min(top)).min(top),
        (4.0 * jw).min(top),
    );
    // kd over the candidates, at the rule's ki; where none of them meets the floor, at half
    // that ki too (its lag at the crossover costs a loop the encoder's count leaves little
    // damping), the better of the two.
    const N: usize = 16;
    let best_kd = |ki: f64| -> Option<(f64, LoopMargins, LoopMargins)> {
        let mut pick: Option<(f64, LoopMargins, LoopMargins)> = None;
        for i in 0..N {
            let kd = if to > from {
                from * (to / from).powf(i as f64 / (N - 1) as f64)
            } else {
                top
            };
            let (nominal, worst) = robust_margins(axis, s.sigma, kp, ki, kd)?;
            if pick
                .as_ref()
                .is_none_or(|p| worst.score(AIM.0, AIM.1) > p.2.score(AIM.0, AIM.1))
            {
                pick = Some((kd, nominal, worst));
            }
            if to <= from {
                break;
            }
        }
        pick
    };
    let mut ki = ki;
    let (mut kd, mut nominal, mut worst) = best_kd(ki)?;
    if halve_ki && worst.over_floor() < 1.0 {
        let (kd2, n2, w2) = best_kd(ki / 2.0)?;
        if w2.over_floor() > worst.over_floor() {
            (ki, kd, nominal, worst) = (ki / 2.0, kd2, n2, w2);
        }
    }
    Some(PositionGains {
        kp,
        ki,
        kd,
        d_filter_hz,
        kd_min,
        kd_max,
        count_limited: kd < 0.5 * jw && kd >= axis.kd_count_limit(),
        nominal,
        worst,
    })
}

/// The device's settings for the position loop `kp`, `ki`, `kd` on `axis` (its current loop,
/// rates, filter, supply and motor), no feedforward.
fn loop_settings(axis: &Axis, kp: f64, ki: f64, kd: f64) -> ControllerParams<6> {
    let mut p: ControllerParams<6> = gms_core::device::default_settings();
    p.pid.kp = kp as f32;
    p.pid.ki = ki as f32;
    p.pid.kd = kd as f32;
    p.pid.d_filter_hz = axis.d_filter_hz as f32;
    p.current.kp = axis.cur_pi.0 as f32;
    p.current.ki = axis.cur_pi.1 as f32;
    p.cur_rate_hz = axis.cur_hz as f32;
    p.pos_rate_hz = axis.pos_hz as f32;
    p.v_supply = axis.v_supply as f32;
    p.motor.r = axis.r as f32;
    p.motor.k_m = axis.k_m as f32;
    p.motor.k_e = axis.k_m as f32;
    p.motor.inertia = axis.inertia as f32;
    p.ff.mode = FfMode::None;
    p
}

/// The linear model's margins (`crate::linear`, `crate::margins`) of the position loop `kp`,
/// `ki`, `kd` on `axis` with the friction's viscous term `sigma` \[N·m·s/rad\]: on the axis as
/// measured, and the least over [`VARIATIONS`] (the controller told the measured figures, the
/// plant varied). `None` when the settings make no model.
pub fn robust_margins(
    axis: &Axis,
    sigma: f64,
    kp: f64,
    ki: f64,
    kd: f64,
) -> Option<(LoopMargins, LoopMargins)> {
    robust_margins_at(axis, sigma, kp, ki, kd, true)
}

/// [`robust_margins`], the variations left out unless `vary` (the worst is then the nominal).
fn robust_margins_at(
    axis: &Axis,
    sigma: f64,
    kp: f64,
    ki: f64,
    kd: f64,
    vary: bool,
) -> Option<(LoopMargins, LoopMargins)> {
    use crate::linear::{LinearAxis, Operating, SmallSignal};
    let p = loop_settings(axis, kp, ki, kd);
    let one = |kx: f64, jx: f64| -> Option<LoopMargins> {
        let ss = SmallSignal {
            r: axis.r,
            l: axis.l,
            k_m: axis.k_m,
            k_e: axis.k_m,
            j: axis.inertia * jx,
            two_mass: None,
            k_act: axis.k_presliding * kx,
            sigma_act: sigma,
            k_gw: 0.0,
            sigma_gw: 0.0,
            rad_per_count: axis.rad_per_count,
        };
        let at = |op: Operating| -> Option<(f64, f64)> {
            let lin = LinearAxis::new(&ss, &p, op).ok()?;
            let (f0, f1) = (2.0, 0.49 * axis.pos_hz);
            let l: Vec<(f64, nalgebra::Complex<f64>)> = (0..400)
                .map(|i| {
                    let f = f0 * (f1 / f0).powf(i as f64 / 399.0);
                    (f, lin.open_loop(f))
                })
                .collect();
            let m = crate::margins::margins(&l);
            // No crossover in the band: nothing to lose where the gain stays under one (a
            // loop at rest on a stiff spring), unstable where it stays above.
            let pm = match (m.phase_margin_deg.is_nan(), l.last()) {
                (false, _) => m.phase_margin_deg,
                (true, Some((_, z))) if z.norm() < 1.0 => f64::INFINITY,
                _ => f64::NEG_INFINITY,
            };
            Some((pm, m.gain_margin_db))
        };
        Some(LoopMargins {
            rest: at(Operating::Rest)?,
            sliding: at(Operating::Sliding)?,
        })
    };
    let nominal = one(1.0, 1.0)?;
    let mut worst = nominal;
    if !vary {
        return Some((nominal, worst));
    }
    for kx in VARIATIONS.0 {
        for jx in VARIATIONS.1 {
            worst = worst.least(&one(kx, jx)?);
        }
    }
    Some((nominal, worst))
}

/// Whether the position loop with `kp`, `ki`, `kd` on `axis` (the friction's viscous term
/// `sigma` \[N·m·s/rad\]) is stable by the linear model on the axis as measured: a positive
/// phase and gain margin at rest and sliding (a loop whose gain stays above one up to the
/// position loop's Nyquist limit, no crossover in the band, is not). `None` when the settings
/// make no model. (A time-domain step through the controller, which this replaced, read the
/// limit twice too high once the current loop ran at 40 kHz: the device rang at 0.7 × it.)
fn stable(axis: &Axis, sigma: f64, kp: f64, ki: f64, kd: f64) -> Option<bool> {
    let (n, _) = robust_margins_at(axis, sigma, kp, ki, kd, false)?;
    let ok = |m: (f64, f64)| m.0 > 0.0 && m.1 > 0.0;
    Some(ok(n.rest) && ok(n.sliding))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The default tune (kp 0.7, kd 2.7e-4, 8 kHz) on 6e-8 kg·m²: ω_d 4500 rad/s (716 Hz),
    /// ω_n 1500 rad/s, kp 0.135, ki 50.6; the loop's characteristic polynomial J s² + kd s +
    /// kp (the integral aside) has the damping ratio asked for. It only softens, and is not
    /// built on a loop damped below half of critical.
    #[test]
    fn the_measuring_loop_is_overdamped_and_filtered_at_its_bandwidth() {
        let m = measuring_loop(0.7, 2.7e-4, 8000.0, 6e-8, 20e3).unwrap();
        assert!((m.kp - 0.135).abs() < 1e-9, "{m:?}");
        assert!((m.ki - 0.135 * 1500.0 / 4.0).abs() < 1e-6, "{m:?}");
        assert!((m.d_filter_hz - 4500.0 / std::f64::consts::TAU).abs() < 1e-9);
        let zeta = 2.7e-4 / (2.0 * (m.kp * 6e-8).sqrt());
        assert!((zeta - MEASURE_DAMPING).abs() < 1e-9, "{zeta}");
        // A softer loop keeps its kp and its filter where they are lower.
        let soft = measuring_loop(0.05, 2.7e-4, 500.0, 6e-8, 20e3).unwrap();
        assert_eq!((soft.kp, soft.d_filter_hz), (0.05, 500.0));
        // A light rotor: the filter held below the Nyquist limit.
        let light = measuring_loop(0.7, 2.7e-4, 8000.0, 6e-9, 10e3).unwrap();
        assert_eq!(light.d_filter_hz, 4500.0);
        // The gear motor's commissioned loop (kd count-limited: ζ 0.03): none.
        assert_eq!(measuring_loop(0.48, 6.5e-5, 8000.0, 2e-6, 20e3), None);
        for bad in [(0.0, 6e-8), (2.7e-4, -1.0), (2.7e-4, f64::NAN)] {
            assert_eq!(measuring_loop(0.7, bad.0, 8000.0, bad.1, 2e4), None);
        }
    }

    #[test]
    fn the_default_motor_gets_the_default_tune() {
        let g = position_gains(&Axis::default_motor(), &SlidingCurve::TABLE1).unwrap();
        eprintln!("{g:?}");
        let d = gms_core::device::default_settings();
        let (ckp, cki) = current_pi(10.0, 0.24e-3, 40e3);
        assert!(
            (ckp / d.current.kp as f64 - 1.0).abs() < 0.01,
            "cur.kp {ckp}"
        );
        assert!(
            (cki / d.current.ki as f64 - 1.0).abs() < 0.01,
            "cur.ki {cki}"
        );
        assert!((g.kp / d.pid.kp as f64 - 1.0).abs() < 0.01, "kp {}", g.kp);
        assert!((g.ki / d.pid.ki as f64 - 1.0).abs() < 0.01, "ki {}", g.ki);
        assert!((g.kd / d.pid.kd as f64 - 1.0).abs() < 0.01, "kd {}", g.kd);
        assert_eq!(g.d_filter_hz, d.pid.d_filter_hz as f64);
        // Table 1's slope at Vs: (Fs - Fc) δ / (e Vs) - σ.
        let slope = 95e-6 * 0.9 / (std::f64::consts::E * 0.2) - 10.5e-6;
        assert!((g.kd_min / slope - 1.0).abs() < 1e-12);
        assert!(g.kd_min < g.kd && g.kd < g.kd_max);
        // The worst variation at the floor, the axis as measured at the aim or above.
        assert!(g.worst.over_floor() >= 1.0, "{:?}", g.worst);
        assert!(g.nominal.score(AIM.0, AIM.1) >= 1.0, "{:?}", g.nominal);
    }

    /// A loop with more inertia takes more derivative gain before it goes unstable; a stiffer
    /// pre-sliding spring takes less (it raises the frequency the loop must damp).
    #[test]
    fn the_stability_limit_moves_with_the_axis() {
        // At one kp (the rule's own kp is chosen per axis, for its margins).
        let kd = |a: &Axis| {
            gains_at(a, &SlidingCurve::TABLE1, 0.45, 0.0, false)
                .unwrap()
                .kd_max
        };
        let base = kd(&Axis::default_motor());
        let heavy = Axis {
            inertia: 1.2e-7,
            ..Axis::default_motor()
        };
        let stiff = Axis {
            k_presliding: 2.5,
            ..Axis::default_motor()
        };
        let free = Axis {
            k_presliding: 0.0,
            ..Axis::default_motor()
        };
        eprintln!(
            "kd_max {base:.3e}, J x2 {:.3e}, spring x2 {:.3e}, no spring {:.3e}",
            kd(&heavy),
            kd(&stiff),
            kd(&free)
        );
        assert!(kd(&heavy) > 1.5 * base);
        assert!(kd(&stiff) < base);
        assert!(kd(&free) > base);
    }
}
