//! Loop-shaping filters on the position loop's current command: two notches and a low-pass,
//! each off at 0 Hz (settings `filt.notch1.*`, `filt.notch2.*`, `filt.lp.f_hz`; run by the
//! controller once per position step, see [`crate::control::controller`]). A notch is the Audio EQ
//! Cookbook's peaking filter cut by `depth_db` at `f_hz` with quality `q` (a finite depth: a
//! resonance is attenuated, not removed, so the loop's phase is disturbed only near it); the
//! low-pass a second-order Butterworth. Each stage runs as the `biquad` crate's direct form 2
//! transposed in f32; its coefficients are the cookbook's as `biquad::Coefficients::from_params`
//! computes them, with the crate's own sine and exponential (a test holds them to the
//! crate's). [`Shaping::response`]
//! evaluates the same coefficients' transfer function on the unit circle (for plots and for
//! the margins a filter would give).

use biquad::{Biquad, Coefficients, DirectForm2Transposed};

/// One notch: a cut of `depth_db` \[dB\] at `f_hz` \[Hz\] (0: off) with quality `q` [-].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Notch {
    /// Centre frequency \[Hz\]; 0 switches the notch off.
    pub f_hz: f32,
    /// Quality factor [-] (centre frequency over bandwidth), 0.1 … 50.
    pub q: f32,
    /// Attenuation at the centre \[dB\], 0 … 60.
    pub depth_db: f32,
}

impl Notch {
    /// A notch switched off, with the quality and depth it takes when a frequency is set
    /// (q 2: a band of half the centre frequency; 20 dB).
    pub const OFF: Notch = Notch {
        f_hz: 0.0,
        q: 2.0,
        depth_db: 20.0,
    };
}

impl Default for Notch {
    fn default() -> Notch {
        Notch::OFF
    }
}

/// The loop-shaping filters' settings.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ShapingParams {
    /// The two notches.
    pub notch: [Notch; 2],
    /// The low-pass's corner frequency \[Hz\]; 0 switches it off.
    pub lp_hz: f32,
}

/// Why a set of filters cannot run at a rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShapingError {
    /// A frequency is negative, not finite, or not below 0.45 × the rate.
    Frequency,
    /// A notch's quality is outside 0.1 … 50.
    Quality,
    /// A notch's depth is outside 0 … 60 dB.
    Depth,
}

impl ShapingError {
    /// The one-line reason.
    pub fn reason(self) -> &'static str {
        match self {
            ShapingError::Frequency => {
                "a filter frequency must be 0 (off) or positive and below 0.45 × the loop rate"
            }
            ShapingError::Quality => "a notch's q must be from 0.1 to 50",
            ShapingError::Depth => "a notch's depth must be from 0 to 60 dB",
        }
    }
}

impl ShapingParams {
    /// Every filter off.
    pub const OFF: ShapingParams = ShapingParams {
        notch: [Notch::OFF; 2],
        lp_hz: 0.0,
    };
}

/// The filters, ready to run at one rate.
#[derive(Debug, Clone, Copy)]
pub struct Shaping {
    coeffs: [Option<Coefficients<f32>>; 3],
    stages: [Option<DirectForm2Transposed<f32>>; 3],
    /// The cascade's last values: `io[0]` its input, `io[i + 1]` the output of stage `i` (not
    /// kept where the stage is off: its output is its input), for a bumpless change of
    /// settings.
    io: [f32; 4],
}

/// `f` checked against the rate: `None` for 0 (off).
fn frequency(f: f32, rate: f32) -> Result<Option<f32>, ShapingError> {
    if f == 0.0 {
        return Ok(None);
    }
    if !(f > 0.0 && f.is_finite() && rate > 0.0 && f < 0.45 * rate) {
        return Err(ShapingError::Frequency);
    }
    Ok(Some(f))
}

/// What a cookbook stage is.
enum Kind {
    /// A peaking filter of this gain \[dB\] (negative: a cut).
    Peaking(f32),
    /// A low-pass.
    LowPass,
}

/// The Audio EQ Cookbook's coefficients of a stage at `f0` \[Hz\] with quality `q` at the
/// rate `fs` \[Hz\], normalised by a0 — the formulas of `biquad::Coefficients::from_params`
/// (the test `gms-core/tests/shaping.rs` holds them to it), with the crate's own sine,
/// cosine and exponential: libm's `sinf`, `cosf` and `powf` that the crate's would link cost
/// the F405's flash 4 KB.
fn cookbook(kind: Kind, f0: f32, q: f32, fs: f32) -> Coefficients<f32> {
    let w0 = core::f32::consts::TAU * f0 / fs;
    let (sin, cos) = crate::control::reference::sin_cos(w0);
    let alpha = sin / (2.0 * q);
    let (b0, b1, b2, a0, a1, a2) = match kind {
        Kind::Peaking(db) => {
            // A = 10^(dB / 40).
            let a = crate::math::exp(db / 40.0 * core::f32::consts::LN_10);
            (
                1.0 + alpha * a,
                -2.0 * cos,
                1.0 - alpha * a,
                1.0 + alpha / a,
                -2.0 * cos,
                1.0 - alpha / a,
            )
        }
        Kind::LowPass => (
            (1.0 - cos) / 2.0,
            1.0 - cos,
            (1.0 - cos) / 2.0,
            1.0 + alpha,
            -2.0 * cos,
            1.0 - alpha,
        ),
    };
    Coefficients {
        a1: a1 / a0,
        a2: a2 / a0,
        b0: b0 / a0,
        b1: b1 / a0,
        b2: b2 / a0,
    }
}

/// The same coefficients (`Coefficients` has no `PartialEq`).
fn same(a: &Coefficients<f32>, b: &Coefficients<f32>) -> bool {
    (a.b0, a.b1, a.b2, a.a1, a.a2) == (b.b0, b.b1, b.b2, b.a1, b.a2)
}

impl Shaping {
    /// The filters of `p` at a sample rate of `rate_hz` \[Hz\], or why not.
    pub fn try_new(p: &ShapingParams, rate_hz: f32) -> Result<Shaping, ShapingError> {
        let mut coeffs = [None; 3];
        for (c, n) in coeffs.iter_mut().zip(&p.notch) {
            let Some(f0) = frequency(n.f_hz, rate_hz)? else {
                continue;
            };
            if !(n.q >= 0.1 && n.q <= 50.0) {
                return Err(ShapingError::Quality);
            }
            if !(n.depth_db >= 0.0 && n.depth_db <= 60.0) {
                return Err(ShapingError::Depth);
            }
            *c = Some(cookbook(Kind::Peaking(-n.depth_db), f0, n.q, rate_hz));
        }
        if let Some(f0) = frequency(p.lp_hz, rate_hz)? {
            coeffs[2] = Some(cookbook(
                Kind::LowPass,
                f0,
                core::f32::consts::FRAC_1_SQRT_2,
                rate_hz,
            ));
        }
        Ok(Shaping {
            coeffs,
            stages: coeffs.map(|c| c.map(DirectForm2Transposed::<f32>::new)),
            io: [0.0; 4],
        })
    }

    /// Filters one sample (the stages in order: notch 1, notch 2, low-pass).
    pub fn run(&mut self, x: f32) -> f32 {
        let mut y = x;
        self.io[0] = x;
        for (s, io) in self.stages.iter_mut().zip(self.io.iter_mut().skip(1)) {
            if let Some(s) = s {
                y = s.run(y);
                *io = y;
            }
        }
        y
    }

    /// Clears the stages' state (the signal at rest).
    pub fn reset(&mut self) {
        for s in self.stages.iter_mut().flatten() {
            s.reset_state();
        }
        self.io = [0.0; 4];
    }

    /// A change of settings without a bump: this cascade (new, at rest) takes the running
    /// state of `old`. A stage whose coefficients are the same keeps its state; a stage that
    /// changed or was switched on starts in the steady state of a constant input at the level
    /// the old stage last gave out (each stage passes 0 Hz unchanged, so the output goes on
    /// from where it was and only the new stage's response to what follows differs). Cheap: no
    /// transcendental function, fit for a control step.
    pub fn take_state_from(&mut self, old: &Shaping) {
        // The old cascade's value after each stage (an off stage passes its input).
        let mut after = [old.io[0]; 3];
        let mut level = old.io[0];
        for (i, a) in after.iter_mut().enumerate() {
            if old.stages.get(i).is_some_and(Option::is_some) {
                level = old.io.get(i + 1).copied().unwrap_or(level);
            }
            *a = level;
        }
        self.io = [old.io[0], after[0], after[1], after[2]];
        for (i, (s, c)) in self.stages.iter_mut().zip(&self.coeffs).enumerate() {
            let (Some(s), Some(c)) = (s, c) else {
                continue;
            };
            match (
                old.stages.get(i).copied().flatten(),
                old.coeffs.get(i).copied().flatten(),
            ) {
                (Some(o), Some(oc)) if same(&oc, c) => {
                    s.s1 = o.s1;
                    s.s2 = o.s2;
                }
                _ => {
                    let level = after.get(i).copied().unwrap_or(0.0);
                    // Direct form 2 transposed at a constant input x = level with output
                    // y = level: s2 = (b2 − a2) x, s1 = s2 + (b1 − a1) x.
                    s.s2 = (c.b2 - c.a2) * level;
                    s.s1 = s.s2 + (c.b1 - c.a1) * level;
                }
            }
        }
    }

    /// The filters' frequency response at `f_hz` \[Hz\] for the rate `rate_hz` \[Hz\]: the
    /// complex gain `(re, im)` of the cascade.
    pub fn response(&self, f_hz: f64, rate_hz: f64) -> (f64, f64) {
        let w = core::f64::consts::TAU * f_hz / rate_hz;
        // z^-1 = e^{-jw}, z^-2 = e^{-2jw}.
        let (c1, s1) = (libm::cos(w), -libm::sin(w));
        let (c2, s2) = (libm::cos(2.0 * w), -libm::sin(2.0 * w));
        let mut h = (1.0, 0.0);
        for c in self.coeffs.iter().flatten() {
            let num = (
                c.b0 as f64 + c.b1 as f64 * c1 + c.b2 as f64 * c2,
                c.b1 as f64 * s1 + c.b2 as f64 * s2,
            );
            let den = (
                1.0 + c.a1 as f64 * c1 + c.a2 as f64 * c2,
                c.a1 as f64 * s1 + c.a2 as f64 * s2,
            );
            let d = den.0 * den.0 + den.1 * den.1;
            let stage = (
                (num.0 * den.0 + num.1 * den.1) / d,
                (num.1 * den.0 - num.0 * den.1) / d,
            );
            h = (h.0 * stage.0 - h.1 * stage.1, h.0 * stage.1 + h.1 * stage.0);
        }
        h
    }
}
