//! `gms-tune`'s command line: every command, option and default (clap's derive).

use std::path::PathBuf;

use clap::{Parser, Subcommand};

/// The gms bench tool.
#[derive(Parser)]
#[command(name = "gms-tune", version, about)]
pub(crate) struct Cli {
    /// Serial port of the device, e.g. /dev/ttyACM0.
    #[arg(long, conflicts_with = "tcp", required_unless_present = "tcp")]
    pub(crate) port: Option<String>,
    /// TCP address of a virtual device (`hil-sim serve --tcp`).
    #[arg(long)]
    pub(crate) tcp: Option<String>,
    /// Reply timeout \[ms\].
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..=600_000))]
    pub(crate) timeout_ms: u64,
    #[command(subcommand)]
    pub(crate) cmd: Cmd,
}

#[derive(Subcommand)]
pub(crate) enum Cmd {
    /// Print a parameter.
    Get {
        /// Parameter path (see `list`).
        path: String,
    },
    /// Set a parameter (nothing changes if the device refuses).
    Set {
        /// Parameter path (see `list`).
        path: String,
        /// New value.
        #[arg(allow_negative_numbers = true)]
        value: String,
    },
    /// Every parameter with value, unit and range.
    List,
    /// Persist the device's parameters (device disabled).
    Save,
    /// Send any request (e.g. `send enable`, `send move 0.01`, `send status`) and print the
    /// reply.
    Send {
        /// The request's words.
        #[arg(required = true, num_args = 1.., allow_negative_numbers = true)]
        words: Vec<String>,
    },
    /// Parameter files: `dump` prints them as TOML, `load FILE` sends them.
    Params {
        #[command(subcommand)]
        action: ParamsCmd,
    },
    /// Record telemetry fields into a CSV file: the first seconds × rate samples (fewer if
    /// the device falls behind).
    Record {
        /// Comma-separated fields: t, pos, ref, error, ff, current, friction.
        #[arg(long, default_value = "t,pos,ref,error,ff")]
        fields: String,
        /// Duration \[s\].
        #[arg(long, default_value_t = 1.0)]
        seconds: f64,
        /// Telemetry rate \[Hz\].
        #[arg(long, default_value_t = 500.0)]
        rate: f64,
        /// Output CSV.
        #[arg(long)]
        out: PathBuf,
    },
    /// Enable, command a step, record it, print its figures (settle time within a band
    /// that allows for quantisation and noise, steady-state error, hunting), write trace.csv,
    /// metrics.json and plot.svg.
    StepTest {
        /// Step size \[rad\].
        #[arg(long, allow_hyphen_values = true)]
        distance: f64,
        /// Recording time \[s\].
        #[arg(long, default_value_t = 0.5)]
        seconds: f64,
        /// Output directory.
        #[arg(long, default_value = "step-test")]
        out: PathBuf,
        /// Print the figures as JSON (raw values, SI) instead of the readable summary.
        #[arg(long)]
        json: bool,
    },
    /// The device's status as a table (what `send status` answers, readable).
    Status {
        /// Print the status as JSON (every key, raw values).
        #[arg(long)]
        json: bool,
    },
    /// A live view of the position error and the friction feedforward (Ctrl-C to stop).
    Watch {
        /// Stop after this many seconds (default: run until interrupted).
        #[arg(long)]
        seconds: Option<f64>,
        /// Refresh period \[ms\].
        #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u64).range(20..=10_000))]
        refresh_ms: u64,
    },
    /// The window: live plots of the telemetry (position, error, feedforward against the
    /// friction estimate, current), the friction loop against position and velocity with the
    /// model over it, the parameter tree (edit, save/load/defaults, dump/load a file), enable,
    /// disable, clear, status and faults, jog, move and step test. The link runs off the UI
    /// thread; a lost link is shown and retried every second.
    #[cfg(feature = "ui")]
    Ui {
        /// Write a PNG of the window after --after seconds, then close it.
        #[arg(long, value_name = "FILE.png")]
        screenshot: Option<PathBuf>,
        /// Seconds after opening for --screenshot.
        #[arg(long, default_value_t = 5.0)]
        after: f64,
        /// A request line sent once the link is up, its reply in the log (repeatable, in
        /// order): e.g. --send enable --send "velocity 0 0.02 0.5 0.5 60".
        #[arg(long, value_name = "LINE")]
        send: Vec<String>,
        /// The page shown first.
        #[arg(long, value_enum, default_value_t = gms_tune::ui::app::Tab::Live)]
        tab: gms_tune::ui::app::Tab,
    },
    /// Identify the axis's friction on the device: the pre-sliding torque staircase (from
    /// rest, after the friction's memory is erased by swings of decaying amplitude), the
    /// sliding velocity sweep
    /// both ways and the frictional-lag run, within a stroke window around where the axis is;
    /// writes their CSVs (for `hil-sim identify`), the report and its plots, the parameter
    /// file. Ctrl-C or a fault ends it with the bridge off, keeping the data so far.
    Identify {
        /// The identified parameter file.
        #[arg(long, default_value = "identified.toml", value_name = "FILE.toml")]
        out: PathBuf,
        /// Directory for the experiments' CSVs, report.txt and the plots.
        #[arg(long, default_value = "identify-report", value_name = "DIR")]
        report: PathBuf,
        /// Maxwell-slip blocks fitted (1 to 6 for --apply/--save: the device holds up to 6).
        #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(1..=32))]
        blocks: u32,
        /// Fit each sliding direction separately ([friction.negative]).
        #[arg(long)]
        asymmetric: bool,
        /// Load the identified set into the device.
        #[arg(long)]
        apply: bool,
        /// Load it and save it on the device (implies --apply).
        #[arg(long)]
        save: bool,
        #[command(flatten)]
        ranges: gms_bench::Ranges,
        /// Print the result as JSON (the identified [friction] table, raw values in SI, and
        /// the report's lines) instead of the readable report.
        #[arg(long)]
        json: bool,
    },
    /// Commission a motor: the current sense at rest, its polarity and the encoder's direction
    /// (fixed by `sense.dir`/`enc.dir`), the winding resistance at standstill, the back-EMF
    /// constant from timed runs both ways; a line per step and a summary; writes a parameter
    /// file whose `[device]` table holds what was found (`params load` takes it). The device is
    /// left as it was unless --apply/--save, which come only after every step succeeded.
    Commission {
        /// The parameter file written.
        #[arg(long, default_value = "motor.toml", value_name = "FILE.toml")]
        out: PathBuf,
        /// The back-EMF runs' base speed [rad/s] (runs at 1, 2 and 3 times it, each way).
        #[arg(long, default_value_t = 1.0)]
        speed: f64,
        /// Load what was found into the device.
        #[arg(long)]
        apply: bool,
        /// Load it and save it (implies --apply).
        #[arg(long)]
        save: bool,
        /// Apply (or save) a loop whose margins at rest are under the floor (40°, 6 dB) too.
        #[arg(long)]
        force: bool,
        /// Print the result as JSON (the settings found, raw values in SI, and the lines).
        #[arg(long)]
        json: bool,
    },
    /// Tune the friction feedforward's gain: the same sine test with reversals at each gain
    /// of a coarse sweep (widened where the error is least at an edge), then repeated around
    /// its optimum; the optimum of a parabola fitted to the mean square, with its uncertainty;
    /// says when the curve is too flat to choose. Prints the time up front, each test, the
    /// result; writes curve.csv and curve.svg. The device's gain is left as it was unless
    /// --apply/--save (and only to a clear optimum, unless --force).
    TuneFf {
        /// Sine amplitude \[rad\] (the axis swings this far from where it is, and back).
        #[arg(long, default_value_t = 2e-3)]
        amplitude: f64,
        /// Sine frequency \[Hz\].
        #[arg(long, default_value_t = 1.0)]
        freq: f64,
        /// Each test's duration \[s\] (the first period is left out of the RMS).
        #[arg(long, default_value_t = 3.0)]
        seconds: f64,
        /// The coarse sweep's lowest gain (widened down if the error is least there).
        #[arg(long, default_value_t = 0.5)]
        from: f64,
        /// The coarse sweep's highest gain (widened up if the error is least there).
        #[arg(long, default_value_t = 1.3)]
        to: f64,
        /// The coarse sweep's gains, evenly spaced (4 to 101).
        #[arg(long, default_value_t = 9)]
        steps: usize,
        /// The refinement's gains around the coarse optimum (4 to 101).
        #[arg(long, default_value_t = 9)]
        fine_steps: usize,
        /// Tests at each of the refinement's gains (1 to 10).
        #[arg(long, default_value_t = 2)]
        repeats: usize,
        /// With --apply/--save: set the fitted optimum even when the curve is too flat to
        /// choose (otherwise the gain stays as it was).
        #[arg(long)]
        force: bool,
        /// Print the result as JSON (raw values, SI) instead of the readable summary.
        #[arg(long)]
        json: bool,
        /// Output directory.
        #[arg(long, default_value = "tune-ff")]
        out: PathBuf,
        /// Set the chosen gain.
        #[arg(long)]
        apply: bool,
        /// Set it and save it (the bridge is switched off to save).
        #[arg(long)]
        save: bool,
    },
    /// Frequency response: a stepped-sine sweep measured on the device (a sine injected at
    /// the current command or the position reference, demodulated over whole periods),
    /// printed point by point; writes frf.csv (f_hz,gain_db,phase_deg,coherence), bode.svg
    /// and, for the open loop, margins.toml. The plant at rest gives the pre-sliding
    /// stiffness. Ctrl-C or a fault ends it with the bridge off, the points so far kept.
    Frf {
        /// What is measured: `plant` (position per current commanded, rad/A), `open` (the loop
        /// gain) or `closed` (position per reference).
        #[arg(long = "loop", value_parser = ["plant", "open", "closed"])]
        lp: String,
        /// Lowest frequency \[Hz\].
        #[arg(long, default_value_t = 10.0)]
        from: f64,
        /// Highest frequency \[Hz\] (below 0.45 × rate.pos_hz; the default loop's phase
        /// crosses −180° near 3.4 kHz).
        #[arg(long, default_value_t = 5000.0)]
        to: f64,
        /// Frequencies, log-spaced (2 to 1000).
        #[arg(long, default_value_t = 40)]
        points: usize,
        /// The sine's amplitude: \[A\] for plant and open (default 1 % of lim.i_max),
        /// \[rad\] for closed (default 20 counts).
        #[arg(long)]
        amplitude: Option<f64>,
        /// Measure while the axis runs at this speed \[rad/s\] (sliding friction: the
        /// rigid-body line), turning round before the soft limits.
        #[arg(long, allow_hyphen_values = true)]
        velocity: Option<f64>,
        /// Periods summed per point, at least (and 0.1 s).
        #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=100_000))]
        periods: u32,
        /// Propose a notch for the largest resonance above the crossover, with the margins it
        /// would give (--loop open).
        #[arg(long)]
        suggest: bool,
        /// Set the proposed notch (implies --suggest).
        #[arg(long)]
        apply: bool,
        /// Print the result as JSON instead of the readable output.
        #[arg(long)]
        json: bool,
        /// Output directory.
        #[arg(long, default_value = "frf")]
        out: PathBuf,
    },
    /// Position map: slow constant-speed runs both ways over whole periods (timed on the
    /// device, captured whole), the torque at each angle fitted with harmonics of the period;
    /// the even part is the torque offset (cogging), the odd part the friction's scale of the
    /// device's model; writes the CSV (angle_rad,torque_nm,friction_scale) and map.svg,
    /// map-scale.svg beside it. Ctrl-C or a fault ends it with the bridge off.
    Map {
        /// The runs' speed [rad/s].
        #[arg(long, default_value_t = 1.0)]
        speed: f64,
        /// Periods run each way.
        #[arg(long, default_value_t = 1.0)]
        revs: f64,
        /// The map's bins (8 to 512 to apply).
        #[arg(long, default_value_t = 512)]
        bins: usize,
        /// The map's period [rad] (default one motor revolution).
        #[arg(long, default_value_t = std::f64::consts::TAU)]
        period: f64,
        /// Harmonics of the period in the fit.
        #[arg(long, default_value_t = 64)]
        order: usize,
        /// The CSV written.
        #[arg(long, default_value = "map.csv")]
        out: PathBuf,
        /// Write the map into the device and switch it on (map.enable 1).
        #[arg(long)]
        apply: bool,
        /// Apply it and save it with the parameters (the bridge is switched off to save).
        #[arg(long)]
        save: bool,
    },
    /// Learning from repetition: a periodic motion played from the device's tables (the
    /// paper's sine, x = A (1 − cos 2πft), from where the axis holds; or a trajectory file of
    /// one period, `t_s,position_rad`), the feedforward correction learned after each period
    /// (iterative learning control on top of the compensation); prints the RMS and peak error
    /// of each iteration, stops when the error grows (the best correction kept), writes
    /// DIR/iterations.csv, DIR/correction.csv and DIR/learning.svg. Ctrl-C or a fault ends it
    /// with the bridge off.
    Learn {
        /// The sine's amplitude [rad] and frequency [Hz] (default 0.05 rad at 1 Hz).
        #[arg(long, num_args = 2, value_names = ["AMPLITUDE", "FREQ"], conflicts_with = "trajectory")]
        sine: Option<Vec<f64>>,
        /// A trajectory of one period: a CSV of `t_s,position_rad` (positions as `move`'s).
        #[arg(long, value_name = "FILE.csv")]
        trajectory: Option<PathBuf>,
        /// Learning updates after the first pass.
        #[arg(long, default_value_t = gms_bench::learn::ITERATIONS)]
        iterations: usize,
        /// The learning gain γ [-] on the loop's own controller (0 < γ ≤ 2).
        #[arg(long, default_value_t = gms_bench::learn::GAIN)]
        gain: f64,
        /// The zero-phase Q filter's corner [Hz] (0: none).
        #[arg(long = "q-filter", default_value_t = gms_bench::learn::Q_HZ)]
        q_filter: f64,
        /// The lead λ [s] of the error on the correction.
        #[arg(long, default_value_t = 0.0)]
        lead: f64,
        /// The directory written.
        #[arg(long)]
        out: PathBuf,
        /// Leave the learned correction playing for the next runs of the table.
        #[arg(long)]
        apply: bool,
    },
}

#[derive(Subcommand)]
pub(crate) enum ParamsCmd {
    /// Print the device's parameters: a `[friction]` table (the compensator's GMS model, the
    /// parameter-file format) and a `[device]` table (everything else, by protocol path).
    Dump,
    /// Send a file written by `dump` (or any parameter file with a GMS `[friction]` of 1 to 6
    /// blocks).
    Load {
        /// The parameter file.
        file: PathBuf,
    },
}
