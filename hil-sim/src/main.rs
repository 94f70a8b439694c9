//! `hil-sim`: the gms simulator and tools.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use gms_core::control::controller::FfMode;
use hil_sim::commands;
use hil_sim::friction_cmd;
use hil_sim::scenario::{DEFAULT_SCENARIO, Scenario};

/// The gms host simulator and tools.
#[derive(Parser)]
#[command(name = "hil-sim", version, about)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Drive a friction model with a position trajectory: t,x in, t,x,v,f out.
    Friction {
        /// Parameter file (TOML with a [friction] table).
        #[arg(long, value_name = "P.toml")]
        params: PathBuf,
        /// Trajectory CSV with a header naming at least `t` \[s\] and `x` [m or rad].
        #[arg(long, value_name = "TRAJ.csv")]
        input: PathBuf,
        /// Output CSV: t,x,v,f (written atomically).
        #[arg(long, value_name = "OUT.csv")]
        output: PathBuf,
    },
    /// Run one closed-loop scenario: DIR/trace.csv, DIR/metrics.json, DIR/plot.svg.
    Run {
        /// Scenario file (TOML); every key optional. Without it, the default scenario.
        #[arg(value_name = "SCENARIO.toml")]
        scenario: Option<PathBuf>,
        /// Output directory (created if missing).
        #[arg(
            long,
            value_name = "DIR",
            required_unless_present = "print_default_scenario"
        )]
        out: Option<PathBuf>,
        /// Print the complete default scenario (every key, with units) and exit.
        #[arg(long)]
        print_default_scenario: bool,
    },
    /// Run the scenario for every feedforward mode over N friction draws; print a table,
    /// write OUT.json and a plot (OUT.svg beside it).
    Compare {
        /// Scenario file (TOML); without it, the default scenario.
        #[arg(value_name = "SCENARIO.toml")]
        scenario: Option<PathBuf>,
        /// Number of friction draws per mode.
        #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u32).range(1..=100_000))]
        runs: u32,
        /// First seed (draw i uses seed + i).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Where to write the JSON summary.
        #[arg(long, value_name = "OUT.json")]
        json: PathBuf,
        /// Worker threads (default: all cores).
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..=256))]
        threads: Option<u32>,
    },
    /// The mismatch study: the device's GMS compensation (its default model, Table 1)
    /// against plants whose actuator friction is another model (4 and 12 blocks, LuGre, a
    /// static map); prints a markdown table (docs/results.md#mismatch).
    Mismatch {
        /// Number of friction draws per plant and mode.
        #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=100_000))]
        runs: u32,
        /// First seed (draw i uses seed + i).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Worker threads (default: all cores).
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..=256))]
        threads: Option<u32>,
    },
    /// The virtual device: the simulated axis in real time behind the bench protocol.
    Serve {
        /// Listen on this TCP address, e.g. 127.0.0.1:7878 (port 0: any free port).
        #[arg(
            long,
            value_name = "ADDR",
            required_unless_present = "pty",
            conflicts_with = "pty"
        )]
        tcp: Option<String>,
        /// Serve on a new pseudo-terminal instead; prints its path (open it like a serial port).
        #[arg(long)]
        pty: bool,
        /// The device's "flash": `save` writes the settings here, a restart reads them.
        #[arg(long, value_name = "FILE")]
        store: Option<PathBuf>,
        /// Scenario file for the plant (its reference is not used); default scenario without.
        #[arg(long, value_name = "SCENARIO.toml")]
        scenario: Option<PathBuf>,
        /// Run the simulated axis this many times faster than the wall clock (0.01 to 1000).
        /// It never skips simulated time: on a host that cannot keep up the device's clock
        /// slows (its replies do not wait for a backlog of steps).
        #[arg(long, default_value_t = 1.0)]
        speed: f64,
    },
    /// Learning from repetition on the virtual device in-process (what `gms-tune learn` does on
    /// a board) over friction draws: prints, per iteration, the median and largest RMS error
    /// over the draws, against the encoder and against the simulated true position.
    Learn {
        /// Scenario file for the plant (its reference is not used); default scenario without.
        #[arg(long, value_name = "SCENARIO.toml")]
        scenario: Option<PathBuf>,
        /// Friction draws.
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=10_000))]
        runs: u32,
        /// First seed (draw i uses seed + i).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// The sine's amplitude [rad] and frequency [Hz] (x = A (1 − cos 2πft)).
        #[arg(long, num_args = 2, value_names = ["AMPLITUDE", "FREQ"], default_values_t = [gms_bench::learn::SINE.0, gms_bench::learn::SINE.1])]
        sine: Vec<f64>,
        /// Learning updates after the first pass.
        #[arg(long, default_value_t = gms_bench::learn::ITERATIONS)]
        iterations: usize,
        /// The learning gain γ [-].
        #[arg(long, default_value_t = gms_bench::learn::GAIN)]
        gain: f64,
        /// The Q filter's corner [Hz] (0: none).
        #[arg(long = "q-filter", default_value_t = gms_bench::learn::Q_HZ)]
        q_filter: f64,
        /// The lead λ [s].
        #[arg(long, default_value_t = 0.0)]
        lead: f64,
        /// Where to write every run's figures as JSON.
        #[arg(long, value_name = "OUT.json")]
        json: Option<PathBuf>,
        /// Worker threads (default: all cores).
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..=256))]
        threads: Option<u32>,
    },
    /// Simulate an identification experiment of the paper on the friction in P.toml.
    Experiment {
        /// presliding, sliding, guideway or lag (frictional lag: speed swept in sliding).
        #[arg(value_parser = ["presliding", "sliding", "guideway", "lag"])]
        kind: String,
        /// Parameter file whose [friction] is the friction measured.
        #[arg(long, value_name = "P.toml")]
        params: PathBuf,
        /// Output CSV.
        #[arg(long, value_name = "DATA.csv")]
        out: PathBuf,
        /// Seed of the friction draw and the noise.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Friction variability per run, ± fraction (the paper saw 0.15).
        #[arg(long, default_value_t = 0.0)]
        variability: f64,
        /// `device`: the bench experiments (those `gms-tune identify` runs) through the
        /// protocol on the device core driving the simulated axis; `ideal`: the paper's
        /// idealised set-up on the friction model alone (any model; always for guideway).
        #[arg(long, default_value = "device", value_parser = ["device", "ideal"])]
        rig: String,
        /// The experiments' ranges on the device rig (as `gms-tune identify` takes them).
        #[command(flatten)]
        ranges: gms_bench::Ranges,
    },
    /// Identify GMS parameters from experiment data; writes a parameter file.
    Identify {
        /// Pre-sliding data (x,f[,dir]).
        #[arg(long, value_name = "PRE.csv")]
        presliding: Option<PathBuf>,
        /// Sliding data (v,f).
        #[arg(long, value_name = "SLIDE.csv")]
        sliding: Option<PathBuf>,
        /// Frictional-lag run (t,x,f; needs --presliding and --sliding): C is fitted to it;
        /// without it, C follows the paper's rule.
        #[arg(long, value_name = "LAG.csv")]
        lag: Option<PathBuf>,
        /// Number of Maxwell-slip blocks.
        #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(1..=32))]
        blocks: u32,
        /// Output parameter file.
        #[arg(long, value_name = "P.toml")]
        out: PathBuf,
        /// Directory for report.txt, virgin.svg and stribeck.svg.
        #[arg(long, value_name = "DIR")]
        report: Option<PathBuf>,
        /// Fit each sliding direction separately ([friction.negative] for v < 0).
        #[arg(long)]
        asymmetric: bool,
    },
    /// The showcase: sinusoid with reversals then fine steps of 1-1000 counts, all four
    /// feedforward modes over 50 friction draws; prints the table, writes plots to ./hil-out/.
    Demo {
        /// Output directory.
        #[arg(long, default_value = "hil-out")]
        out: PathBuf,
        /// Number of friction draws per mode.
        #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u32).range(1..=100_000))]
        runs: u32,
    },
}

fn load_scenario(path: Option<&Path>) -> Result<Scenario, String> {
    match path {
        Some(p) => Scenario::load(p).map_err(|e| e.to_string()),
        None => Ok(Scenario::default()),
    }
}

fn threads(n: Option<u32>) -> usize {
    n.map(|n| n as usize)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

fn compare_and_write(
    sc: &Scenario,
    runs: u32,
    seed: u64,
    json: &Path,
    threads: usize,
) -> Result<(), String> {
    let (cmp, traces) = commands::compare(sc, runs as usize, seed, threads, true)?;
    print!("{}", commands::table(&cmp, sc.plant.rad_per_count));
    let text = serde_json::to_string_pretty(&cmp).map_err(|e| e.to_string())?;
    gms_ident::io::write_atomic(json, text.as_bytes())?;
    let svg = json.with_extension("svg");
    // The zoomed panel starts at the first step segment.
    let segs = sc.segments()?;
    let mut t = 0.0f64;
    let mut zoom = 0.0f64;
    for s in &segs {
        if matches!(
            s,
            gms_core::control::reference::Segment::Step { .. }
                | gms_core::control::reference::Segment::Move { .. }
        ) {
            zoom = t;
            break;
        }
        t += s.duration() as f64;
    }
    let named: Vec<(&str, &[gms_ident::trace::TraceRow])> = FfMode::ALL
        .iter()
        .zip(&traces)
        .map(|(m, t)| (m.name(), t.as_slice()))
        .collect();
    gms_ident::plot::compare_plot(
        &svg,
        &format!("position error by feedforward mode (draw seed {seed})"),
        &named,
        sc.plant.rad_per_count,
        zoom,
    )?;
    println!("wrote {} and {}", json.display(), svg.display());
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.cmd {
        Cmd::Friction {
            params,
            input,
            output,
        } => friction_cmd::run(&params, &input, &output)
            .map(|(_, warnings)| {
                for w in warnings {
                    eprintln!("warning: {w}");
                }
            })
            .map_err(String::from),
        Cmd::Run {
            scenario,
            out,
            print_default_scenario,
        } => {
            if print_default_scenario {
                print!("{DEFAULT_SCENARIO}");
                Ok(())
            } else {
                load_scenario(scenario.as_deref()).and_then(|sc| {
                    let out = out.unwrap_or_else(|| PathBuf::from("hil-out"));
                    let res = commands::run(&sc, &out)?;
                    let m = res.metrics;
                    let c = sc.plant.rad_per_count;
                    println!(
                        "rms error {:.2} counts, max {:.1} counts, reversal peak {:.1} counts, \
                         settle {:.1} ms; wrote {}/trace.csv, metrics.json, plot.svg",
                        m.rms_error / c,
                        m.max_error / c,
                        m.reversal_error / c,
                        m.settle_time * 1e3,
                        out.display()
                    );
                    Ok(())
                })
            }
        }
        Cmd::Compare {
            scenario,
            runs,
            seed,
            json,
            threads: t,
        } => load_scenario(scenario.as_deref())
            .and_then(|sc| compare_and_write(&sc, runs, seed, &json, threads(t))),
        Cmd::Mismatch {
            runs,
            seed,
            threads: t,
        } => (|| {
            let rows = hil_sim::study::mismatch(runs as usize, seed, threads(t), true)?;
            let rpc = Scenario::default().plant.rad_per_count;
            print!("{}", hil_sim::study::table(&rows, rpc));
            Ok(())
        })(),
        Cmd::Serve {
            tcp,
            pty,
            store,
            scenario,
            speed,
        } => load_scenario(scenario.as_deref()).and_then(|sc| {
            let endpoint = match (tcp, pty) {
                (Some(tcp), _) => hil_sim::device::Endpoint::Tcp(
                    std::net::TcpListener::bind(&tcp)
                        .map_err(|e| format!("--tcp {tcp}: cannot listen: {e}"))?,
                ),
                #[cfg(unix)]
                (None, true) => hil_sim::device::Endpoint::Pty,
                #[cfg(not(unix))]
                (None, true) => {
                    return Err("--pty needs a Unix pseudo-terminal: use --tcp ADDR here".into());
                }
                _ => return Err("give --tcp ADDR or --pty".into()),
            };
            hil_sim::device::serve(sc, endpoint, store, speed, |addr, fault| {
                if let Some(f) = fault {
                    eprintln!("warning: {f} (fault invalid_params latched: clear to enable)");
                }
                println!("listening on {addr}");
                use std::io::Write as _;
                let _ = std::io::stdout().flush();
            })
            .map_err(String::from)
        }),
        Cmd::Experiment {
            kind,
            params,
            out,
            seed,
            variability,
            rig,
            ranges,
        } => (|| {
            use hil_sim::bench::run_on_device;
            use hil_sim::experiment::{Kind, Setup, run};
            if !(0.0..0.9).contains(&variability) {
                return Err("--variability must be in [0, 0.9)".to_string());
            }
            let pf = gms_ident::paramfile::ParamFile::load(&params).map_err(|e| e.to_string())?;
            pf.friction
                .build()
                .map_err(|e| format!("{}: {e}", params.display()))?;
            let k = match kind.as_str() {
                "presliding" => Kind::Presliding,
                "sliding" => Kind::Sliding,
                "lag" => Kind::Lag,
                _ => Kind::Guideway,
            };
            let text = if rig == "device" && k != Kind::Guideway {
                run_on_device(k, &pf.friction, variability, seed, &ranges)?
            } else {
                let r = &ranges;
                let given = [r.torque_step, r.v_min, r.v_max, r.window]
                    .iter()
                    .any(Option::is_some)
                    || r.speeds.is_some()
                    || r.no_erase;
                if given {
                    return Err("--torque-step, --v-min, --v-max, --speeds, --window and \
                                --no-erase plan the device rig's experiments: not with --rig \
                                ideal or the guideway"
                        .into());
                }
                run(
                    k,
                    &pf.friction,
                    &Setup::paper(k, &pf.friction, variability),
                    seed,
                )?
            };
            gms_ident::io::write_atomic(&out, text.as_bytes())?;
            println!("{} rows to {}", text.lines().count() - 1, out.display());
            Ok(())
        })(),
        Cmd::Identify {
            presliding,
            sliding,
            lag,
            blocks,
            out,
            report,
            asymmetric,
        } => (|| {
            let id = gms_ident::identify::identify_from(&gms_ident::identify::Inputs {
                presliding: presliding.as_deref(),
                sliding: sliding.as_deref(),
                lag: lag.as_deref(),
                blocks: blocks as usize,
                asymmetric,
            })?;
            for l in &id.report {
                println!("{l}");
            }
            if let Some(dir) = &report {
                gms_ident::identify::write_report(&id, dir)?;
                println!("report in {}", dir.display());
            }
            let file = gms_ident::paramfile::ParamFile {
                friction: id.spec,
                device: None,
            };
            let text = format!(
                "# identified by hil-sim identify\n{}",
                id.report
                    .iter()
                    .map(|l| format!("# {l}\n"))
                    .collect::<String>()
                    + &file.to_toml()
            );
            gms_ident::io::write_atomic(&out, text.as_bytes())?;
            println!("wrote {}", out.display());
            Ok(())
        })(),
        Cmd::Learn {
            scenario,
            runs,
            seed,
            sine,
            iterations,
            gain,
            q_filter,
            lead,
            json,
            threads: t,
        } => (|| {
            let sc = load_scenario(scenario.as_deref())?;
            let plan = gms_bench::learn::LearnPlan {
                path: gms_bench::learn::Path::Sine {
                    amplitude: sine.first().copied().unwrap_or(f64::NAN),
                    freq: sine.get(1).copied().unwrap_or(f64::NAN),
                },
                iterations,
                gain,
                q_hz: q_filter,
                lead_s: lead,
                ..gms_bench::learn::LearnPlan::default()
            };
            plan.check().map_err(|e| e.to_string())?;
            let rs = hil_sim::learn::learn_draws(&sc, runs as usize, seed, &plan, threads(t))?;
            print!("{}", hil_sim::learn::table(&rs));
            println!("{}", hil_sim::learn::scatter_line(&rs));
            for r in rs.iter().filter(|r| r.stopped.is_some()) {
                println!(
                    "seed {}: stopped ({})",
                    r.seed,
                    r.stopped.as_deref().unwrap_or("")
                );
            }
            if let Some(path) = json {
                let text = serde_json::to_string_pretty(&rs).map_err(|e| e.to_string())?;
                gms_ident::io::write_atomic(&path, text.as_bytes()).map_err(|e| e.to_string())?;
            }
            Ok(())
        })(),
        Cmd::Demo { out, runs } => (|| {
            let sc = Scenario::default();
            std::fs::create_dir_all(&out)
                .map_err(|e| format!("{}: cannot create: {e}", out.display()))?;
            compare_and_write(&sc, runs, 1, &out.join("compare.json"), threads(None))?;
            for mode in FfMode::ALL {
                let mut one = sc.clone();
                one.set_controller(
                    gms_core::protocol::ParamId::FfMode.path(),
                    toml::Value::String(mode.name().into()),
                );
                commands::run(&one, &out.join(format!("run-{}", mode.name())))?;
            }
            let dirs: Vec<String> = FfMode::ALL
                .iter()
                .map(|m| format!("{}/run-{}/", out.display(), m.name()))
                .collect();
            println!(
                "wrote {} (trace.csv, metrics.json, plot.svg)",
                dirs.join(", ")
            );
            Ok(())
        })(),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}
