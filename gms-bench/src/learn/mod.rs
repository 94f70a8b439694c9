//! Learning from repetition on a device: a periodic motion played from the device's tables
//! (`table …`), and after each period the feedforward correction learned from that period's
//! error ([`crate::ilc`]) and swapped in at the start of the next-but-one (the device plays on
//! while the host reads, learns and uploads: one iteration is two periods).
//!
//! The design's choices (docs/learning.md):
//!
//! - **Learning filter** `L = γ (C + J s² + K(t)) e^{jωλ}`, the inverse of the process
//!   sensitivity `P / (1 + P C)`: the device's own position controller `C` (its PID and
//!   filters, read from the device, [`gms_ident::linear::PositionController`]), the rigid
//!   axis's `1/P = J s²` (`motor.inertia`), plus the friction's local stiffness `K(t)` along
//!   the path (the device's GMS model run over the reference: all of Σk just after a reversal,
//!   nothing once sliding). A correction `L e` changes the next period's error by about `−γ e`
//!   whether the axis slides or sticks, whatever the gains. γ is dimensionless; default 0.3:
//!   the period's error on the default loop holds about 0.4 counts RMS that does not repeat
//!   (the encoder's quantisation answered by the loop), which a small gain averages out of
//!   the correction, while the reversals' peaks want a quick one (docs/learning.md: on the
//!   default 20 kHz loop γ 0.3 and Q 400 Hz reach a peak of 2.3 counts after ten iterations,
//!   γ 0.15 and Q 300 Hz 3.4).
//! - **Lead** λ (default 0; negative leads diverge, +0.5 ms is no better): added to the
//!   half-bin shift of the device's error bins (each the mean over the `steps` steps after
//!   its point).
//! - **Q**: a zero-phase second-order Butterworth at `q_hz` (default 400 Hz: the error at a
//!   reversal changes within a few milliseconds; 30-60 Hz leaves it unlearned) over the period.
//! - **Stop**: the RMS averaged over the last `patience` iterations (default 5) risen 25 %
//!   above its lowest such average; the best correction is then kept. The sine test's RMS
//!   scatters by ±15 % from one period to the next on the default plant (its reversals'
//!   stick-slip is not the same twice), so a single rise says nothing.

mod device;

mod path;

pub use device::*;

pub use path::*;

use crate::Error;
use gms_ident::linear::PositionController;

use gms_core::control::table::{Geometry, TableReport, TableState, Which};
use gms_core::protocol::{self, Command, TableCmd};

use crate::client::{Bench, check_faults, guarded, status};
use crate::ilc::{Iteration, Learner, LearningFilter, QFilter, Stop};

/// What the learning gave.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Learned {
    /// The table played.
    pub table: Option<Table>,
    /// Each iteration's figures (from 0: the first pass), RMS and peak over every step
    /// \[counts\].
    pub iterations: Vec<Iteration>,
    /// Each iteration's error at the points \[counts\] (each bin the mean over its steps).
    pub errors: Vec<Vec<f64>>,
    /// The correction kept (the best) \[N·m at the points\].
    pub correction: Vec<f64>,
    /// Why it stopped early, if it did.
    pub stopped: Option<Stop>,
    /// The device's periods each iteration was measured in.
    pub periods: Vec<u32>,
    /// The position step the run started at (the device's count: period `p` is the steps
    /// from `started + p × points × steps`).
    pub started: u64,
}

/// Iterations the repeatability is taken over (the last ones).
pub const REPEAT_ITERATIONS: usize = 5;

/// What of the error repeats over the learning's last iterations and what does not
/// \[counts\]: the part that repeats is what more learning could still take, the rest its
/// floor. From the device's figures alone: the error at the points (each the mean over its
/// bin's steps) split by [`crate::ilc::decompose`] into its mean over the iterations and the
/// scatter about it; the part that does not repeat step by step is what of the periods'
/// mean square (their RMS over every step) the repeating part leaves, since within a bin the
/// reading's quantisation and the loop's answer to it average out of the points. The
/// corrections differ from one of these iterations to the next by γ of an error that
/// mostly does not repeat, a share of about γ² of its square: negligible.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Repeat {
    /// Iterations it is taken over.
    pub iterations: usize,
    /// The RMS over every step of them.
    pub rms: f64,
    /// What repeats (at the points).
    pub repeating: f64,
    /// What does not: `sqrt(rms² − repeating²)`.
    pub not_repeating: f64,
}

impl Repeat {
    /// One line for the command line and the window.
    pub fn line(&self) -> String {
        format!(
            "over the last {} iterations: {:.3} counts RMS, {:.3} of it repeating (what more \
             learning could take), {:.3} not (its floor)",
            self.iterations, self.rms, self.repeating, self.not_repeating
        )
    }
}

impl Learned {
    /// What of the error repeats over the last [`REPEAT_ITERATIONS`] iterations (or as many
    /// as there are, at least 3); `None` with fewer.
    pub fn repeat(&self) -> Option<Repeat> {
        let n = self.errors.len().min(self.iterations.len());
        let k = n.min(REPEAT_ITERATIONS);
        if k < 3 {
            return None;
        }
        let (_, repeating, _) = crate::ilc::decompose(&self.errors[n - k..n])?;
        let ms = self.iterations[n - k..n]
            .iter()
            .map(|it| it.rms * it.rms)
            .sum::<f64>()
            / k as f64;
        let repeating = repeating.min(ms.sqrt());
        Some(Repeat {
            iterations: k,
            rms: ms.sqrt(),
            repeating,
            not_repeating: (ms - repeating * repeating).max(0.0).sqrt(),
        })
    }
}

/// The first complete period after `after` played wholly with the correction `generation`:
/// its number, RMS and peak \[counts\] and its error at the points, all of the same period.
/// The device holds that period until the host asks for the next one (`table next`) or sends
/// a new correction: the periods that end while the host reads, however slow the link, play
/// on without replacing it.
fn read_period(
    b: &mut impl Bench,
    t: &Table,
    after: Option<u32>,
    generation: u32,
) -> Result<(u32, f64, f64, Vec<f64>), Error> {
    let (p, rms, peak) = wait_period(b, t.period(), after, generation)?;
    let e = read_values(b, Which::Err, t.points)?;
    // Held: nothing but this host's own requests replaces it (checked all the same).
    if table_status(b)?.done.map(|d| d.0) != Some(p) {
        return Err(Error::Device(format!(
            "period {p}'s error was replaced while it was read (another client?)"
        )));
    }
    Ok((p, rms, peak, e))
}

/// Periods the device may complete while the host waits for the one it wants: the one under
/// way when a correction is sent, the one the correction waits for, its own, and room.
const WAIT_PERIODS: u32 = 10;

/// Waits until the device holds a complete period after `after` played with the correction
/// `generation`; returns its figures. Fails when the run has stopped or faulted, or when the
/// device has completed [`WAIT_PERIODS`] periods without one (counted by the device: the
/// bound is in the device's time, whatever the host's or the link's speed).
fn wait_period(
    b: &mut impl Bench,
    period_s: f64,
    after: Option<u32>,
    generation: u32,
) -> Result<(u32, f64, f64), Error> {
    let mut first = None;
    loop {
        let s = table_status(b)?;
        if let Some((p, g, rms, peak)) = s.done
            && g == generation
            && s.held
            && after.is_none_or(|a| p > a)
        {
            return Ok((p, rms, peak));
        }
        if !s.playing {
            check_faults(b)?;
            return Err(Error::Device(
                "the table run ended before the period came (bridge off?)".into(),
            ));
        }
        let from = *first.get_or_insert(s.period);
        if s.period > from + WAIT_PERIODS {
            check_faults(b)?;
            return Err(Error::Device(format!(
                "no period of correction {generation} held after {WAIT_PERIODS} periods"
            )));
        }
        // A twenty-fifth of a period of device time between looks.
        b.wait(period_s / 25.0)?;
    }
}

/// Runs the learning on the device: the table set (the device refuses a path beyond its
/// limits, and nothing changes: the bridge as it was, nothing moves), the axis brought to its
/// start, the periods played with
/// the correction learned after each (`progress` called with each iteration's figures), the
/// best correction kept; `apply` leaves it set for the next runs of the table, otherwise the
/// table plays no correction after. The axis holds at the table's start after; the bridge is
/// off on failure.
pub fn learn(
    b: &mut impl Bench,
    plan: &LearnPlan,
    mut progress: impl FnMut(&Iteration),
    apply: bool,
) -> Result<Learned, Error> {
    plan.check()?;
    // The path first, checked whole by the device: a refusal changes nothing (the bridge
    // as it was, nothing moves).
    let settings = crate::settings::read(b)?;
    let ctrl = PositionController::new(&settings).map_err(Error::Device)?;
    let rpc = crate::client::rad_per_count(b)?;
    let pos_hz = f64::from(settings.pos_rate_hz);
    let st = status(b)?;
    // Where the axis holds: its reference (the position plus the error) [counts].
    let held = |st: &gms_core::device::StatusReply| st.pos / rpc + f64::from(st.error_counts);
    let t = plan_table(&plan.path, pos_hz, rpc, held(&st))?;
    set_table(b, &t)?;
    guarded(b, |b| {
        b.enable()?;
        let st = status(b)?;
        if (t.start_rad() - held(&st) * rpc).abs() > 0.5 * rpc {
            crate::client::move_to(b, t.start_rad(), 0.5)?;
            b.wait(0.2)?;
        }
        let n = t.points as usize;
        let rate = 1.0 / t.dt();
        // The bins are centred (steps − 1)/2 position steps after their points.
        let centre = (f64::from(t.steps) - 1.0) / 2.0 / pos_hz;
        // The inverse of the process sensitivity P / (1 + P C): C plus the rigid plant's
        // 1/P = J s² (−J ω² on the jω axis); K(t) comes below, pointwise.
        let inertia = f64::from(settings.motor.inertia);
        let l = LearningFilter::shaped(n, rate, plan.gain, plan.lead_s - centre, |f| {
            (ctrl.torque(f) - inertia * (std::f64::consts::TAU * f).powi(2)) * rpc
        });
        let l = if plan.stiffness {
            let k = friction_stiffness(&settings, &t);
            l.with_pointwise(k.iter().map(|k| plan.gain * k * rpc).collect())
        } else {
            l
        };
        let q = QFilter::new(plan.q_hz, rate);
        let mut learner = Learner::new(l, q, plan.patience);
        let mut out = Learned {
            table: Some(t.clone()),
            ..Learned::default()
        };
        // Played until stopped (a host that reads, learns and uploads slower than a period
        // costs periods, not the run); a lost link ends it at its period's end.
        b.send(Command::Table(TableCmd::Run(
            gms_core::control::table::TABLE_MAX_PERIODS,
        )))?;
        out.started = table_status(b)?.started;
        // The first period starts from rest: the first pass is the next one held, in the
        // periodic state the learning works on.
        let (first, _, _) = wait_period(b, t.period(), None, 0)?;
        b.send(Command::Table(TableCmd::Next))?;
        let mut last = Some(first);
        for i in 0..=plan.iterations {
            // The correction learned after iteration i − 1 is generation i.
            let (p, rms, peak, e) = read_period(b, &t, last, i as u32)?;
            last = Some(p);
            out.periods.push(p);
            let r = learner.learn_measured(&e, rms, peak);
            out.errors.push(e);
            match r {
                Ok(it) => progress(&it),
                Err(stop) => {
                    if let Some(it) = learner.history().last() {
                        progress(it);
                    }
                    out.stopped = Some(stop);
                    break;
                }
            }
            if i == plan.iterations {
                break;
            }
            use_correction(b, learner.correction())?;
        }
        b.send(Command::Table(TableCmd::Stop))?;
        for _ in 0..200 {
            if !table_status(b)?.playing {
                break;
            }
            b.wait(t.period() / 20.0)?;
        }
        check_faults(b)?;
        out.iterations = learner.history().to_vec();
        out.correction = learner.best().to_vec();
        if apply {
            use_correction(b, &out.correction)?;
        } else {
            b.send(Command::Table(TableCmd::CorrOff))?;
        }
        Ok(out)
    })
}

/// The compensator's friction model's local stiffness along the table's path \[N·m/rad at
/// each point\]: the change of its elastic force over the interval after each point per
/// displacement (the blocks that stick: all of Σk just after a reversal, none once
/// sliding), the model (`gms.*` and the reflected guideway) run over two periods of the
/// reference at the position rate, the second kept.
pub fn friction_stiffness(s: &gms_core::protocol::Settings, t: &Table) -> Vec<f64> {
    use gms_core::{FrictionModel, Gms};
    let ff = &s.ff;
    let mut act = Gms::try_new(ff.actuator).ok();
    let mut guide = ff.guideway.and_then(|g| Gms::try_new(g).ok());
    let ratio = ff.ratio;
    let sum_k = |g: &Option<Gms<6>>, r: f32| {
        g.as_ref().map_or(0.0, |g| {
            g.params()
                .blocks
                .iter()
                .map(|b| f64::from(b.k * r * r))
                .sum::<f64>()
        })
    };
    let k_max = sum_k(&act, 1.0) + sum_k(&guide, ratio);
    let n = t.points as usize;
    let steps = t.steps as usize;
    let dt = 1.0 / t.rate as f32;
    let rpc = t.rad_per_count;
    let elastic = |a: &Option<Gms<6>>, g: &Option<Gms<6>>| -> f64 {
        let f = |m: &Option<Gms<6>>, r: f32| {
            m.as_ref()
                .map_or(0.0, |m| f64::from((m.force() - m.viscous_force()) * r))
        };
        f(a, 1.0) + f(g, ratio)
    };
    // The reference at every step, as the device plays it (its points in f32, its cubic).
    let x_at = |i: usize| -> f64 {
        let k = i / steps;
        let s = (i % steps) as f32 / steps as f32;
        let p = |j: usize| t.values[j % n] as f32;
        let (x, _, _) =
            gms_core::control::table::catmull_rom([p(k + n - 1), p(k), p(k + 1), p(k + 2)], s);
        f64::from(x) * rpc
    };
    let mut out = vec![0.0; n];
    let mut x_prev = x_at(0);
    let mut at_point = (elastic(&act, &guide), x_prev);
    for round in 0..2 {
        for i in 0..n * steps {
            let x = x_at((i + 1) % (n * steps));
            let dx = (x - x_prev) as f32;
            x_prev = x;
            if let Some(a) = &mut act {
                a.advance(dx, dt);
            }
            if let Some(g) = &mut guide {
                g.advance(ratio * dx, dt);
            }
            if (i + 1) % steps == 0 {
                let now = (elastic(&act, &guide), x);
                let k = (i + 1) / steps - 1;
                let (df, ddx) = (now.0 - at_point.0, now.1 - at_point.1);
                if round == 1 {
                    out[k] = if ddx.abs() > 1e-12 {
                        (df / ddx).clamp(0.0, k_max)
                    } else {
                        k_max
                    };
                }
                at_point = now;
            }
        }
    }
    out
}

/// `iterations.csv`: `iteration,rms_counts,peak_counts`.
pub fn iterations_csv(l: &Learned) -> String {
    let mut s = String::from("iteration,rms_counts,peak_counts\n");
    for it in &l.iterations {
        s.push_str(&format!("{},{},{}\n", it.n, it.rms, it.peak));
    }
    s
}

/// `correction.csv`: `t_s,position_rad,correction_nm` at the table's points.
pub fn correction_csv(l: &Learned) -> String {
    let mut s = String::from("t_s,position_rad,correction_nm\n");
    if let Some(t) = &l.table {
        for (k, u) in l.correction.iter().enumerate() {
            let x = (t.origin as f64 + t.values.get(k).copied().unwrap_or(0.0)) * t.rad_per_count;
            s.push_str(&format!("{},{},{}\n", k as f64 * t.dt(), x, u));
        }
    }
    s
}
