//! `gms-tune`: the bench tool. Talks the gms command protocol to the firmware over a serial
//! port (USB CDC-ACM) or to `hil-sim serve` over TCP.

use gms_core::protocol::Command;
use std::path::Path;
use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;
use cli::{Cli, Cmd, ParamsCmd};
use gms_ident::paramfile::ParamFile;
use gms_tune::{Link, LinkError, parse_telemetry};

mod cli;
mod commission;
mod frf;
mod identify;
mod learn;
mod map;
mod tracked;
mod tune_ff;

/// Exit 1: the device refused or did not answer; exit 2: bad arguments or no link.
pub(crate) enum Fail {
    Device(String),
    Usage(String),
}

impl From<LinkError> for Fail {
    fn from(e: LinkError) -> Fail {
        Fail::Device(e.to_string())
    }
}

fn dump(link: &mut Link) -> Result<String, Fail> {
    let file = device_params(link)?;
    Ok(format!("# gms-tune params dump\n{}", file.to_toml()))
}

/// The device's parameters as a parameter file ([`gms_tune::params::read`]).
pub(crate) fn device_params(link: &mut Link) -> Result<ParamFile, Fail> {
    gms_tune::params::read(link).map_err(Fail::from)
}

/// `params load FILE`: the file sent as one set ([`gms_tune::params::load`]).
pub(crate) fn load(link: &mut Link, file: &Path) -> Result<usize, Fail> {
    gms_tune::params::load(link, file).map_err(|e| match e {
        gms_tune::params::LoadError::File(m) => Fail::Usage(m),
        gms_tune::params::LoadError::Device(m) => Fail::Device(m),
    })
}

fn record(link: &mut Link, fields: &str, rate: f64, seconds: f64) -> Result<Vec<Vec<f64>>, Fail> {
    Ok(link.record(fields, rate, seconds)?)
}

fn write_csv(path: &Path, fields: &str, rows: &[Vec<f64>]) -> Result<(), Fail> {
    let mut text = format!("{fields}\n");
    for r in rows {
        let cells: Vec<String> = r.iter().map(|v| format!("{v}")).collect();
        text += &cells.join(",");
        text.push('\n');
    }
    gms_ident::io::write_atomic(path, text.as_bytes()).map_err(|e| Fail::Usage(e.to_string()))
}

fn run(cli: Cli) -> Result<(), Fail> {
    let timeout = Duration::from_millis(cli.timeout_ms);
    #[cfg(feature = "ui")]
    if let Cmd::Ui {
        screenshot,
        after,
        send,
        tab,
    } = &cli.cmd
    {
        let endpoint = match (&cli.port, &cli.tcp) {
            (Some(p), _) => gms_tune::ui::Endpoint::Serial(p.clone()),
            (None, Some(a)) => gms_tune::ui::Endpoint::Tcp(a.clone()),
            (None, None) => return Err(Fail::Usage("give --port or --tcp".into())),
        };
        if !(after.is_finite() && *after >= 0.0) {
            return Err(Fail::Usage(format!("--after {after}: seconds, 0 or more")));
        }
        let shot = screenshot.clone().map(|path| gms_tune::ui::Screenshot {
            path,
            after: *after,
        });
        return gms_tune::ui::run(endpoint, timeout, send.clone(), *tab, shot)
            .map_err(Fail::Device);
    }
    let mut link = match (&cli.port, &cli.tcp) {
        (Some(p), _) => Link::serial(p, timeout),
        (None, Some(a)) => Link::tcp(a, timeout),
        (None, None) => Err("give --port or --tcp".into()),
    }
    .map_err(Fail::Usage)?;
    match cli.cmd {
        Cmd::Get { path } => println!("{}", link.ask(Command::Get(&path))?.1),
        Cmd::Set { path, value } => {
            link.ask(Command::Set(&path, &value))?;
        }
        Cmd::List => {
            for l in link.ask(Command::List)?.0 {
                println!("{l}");
            }
        }
        Cmd::Save => {
            link.ask(Command::Save)?;
        }
        Cmd::Send { words } => {
            let text = link.console_text(&words.join(" "))?;
            if !text.is_empty() {
                println!("{text}");
            }
        }
        Cmd::Params {
            action: ParamsCmd::Dump,
        } => print!("{}", dump(&mut link)?),
        Cmd::Params {
            action: ParamsCmd::Load { file },
        } => {
            let n = load(&mut link, &file)?;
            eprintln!("sent {n} parameters");
        }
        Cmd::Record {
            fields,
            seconds,
            rate,
            out,
        } => {
            if !(seconds > 0.0 && seconds <= 3600.0 && rate > 0.0 && rate <= 1000.0) {
                return Err(Fail::Usage(
                    "--seconds in (0, 3600], --rate in (0, 1000]".into(),
                ));
            }
            let rows = record(&mut link, &fields, rate, seconds)?;
            write_csv(&out, &fields, &rows)?;
            eprintln!("{} samples to {}", rows.len(), out.display());
        }
        Cmd::Status { json } => {
            let st = link.status()?;
            if json {
                println!("{}", gms_tune::run::status_json(&st));
            } else {
                for l in gms_tune::run::status_table(&st) {
                    println!("{l}");
                }
            }
        }
        Cmd::StepTest {
            distance,
            seconds,
            out,
            json,
        } => {
            if !(distance.is_finite() && seconds > 0.0 && seconds <= 60.0) {
                return Err(Fail::Usage(
                    "--distance finite, --seconds in (0, 60]".into(),
                ));
            }
            std::fs::create_dir_all(&out)
                .map_err(|e| Fail::Usage(format!("{}: {e}", out.display())))?;
            let (six, trace, m, rpc) = gms_tune::run::step_test(&mut link, distance, seconds)?;
            let rows: Vec<Vec<f64>> = six.iter().map(|r| r.to_vec()).collect();
            write_csv(&out.join("trace.csv"), gms_tune::run::STEP_FIELDS, &rows)?;
            let text = serde_json::to_string_pretty(&m).map_err(|e| Fail::Usage(e.to_string()))?;
            if json {
                println!("{text}");
            } else {
                for l in gms_tune::run::step_summary(&m, distance, &trace, rpc) {
                    println!("{l}");
                }
            }
            gms_ident::io::write_atomic(&out.join("metrics.json"), text.as_bytes())
                .map_err(|e| Fail::Usage(e.to_string()))?;
            gms_ident::plot::run_plot(
                &out.join("plot.svg"),
                "gms-tune step-test",
                &trace,
                rpc,
                gms_ident::plot::FrictionSource::Estimate,
            )
            .map_err(Fail::Usage)?;
        }
        Cmd::Watch {
            seconds,
            refresh_ms,
        } => watch(&mut link, seconds, Duration::from_millis(refresh_ms))?,
        Cmd::Commission {
            out,
            speed,
            apply,
            save,
            force,
            json,
        } => commission::run(&mut link, &out, speed, apply, save, force, json)?,
        Cmd::TuneFf {
            amplitude,
            freq,
            seconds,
            from,
            to,
            steps,
            fine_steps,
            repeats,
            force,
            json,
            out,
            apply,
            save,
        } => tune_ff::run(
            &mut link,
            &tune_ff::Args {
                plan: gms_bench::TuneFfPlan {
                    amp: amplitude,
                    freq,
                    seconds,
                    from,
                    to,
                    steps,
                    fine_steps,
                    repeats,
                },
                out,
                apply,
                save,
                force,
                json,
            },
        )?,
        Cmd::Frf {
            lp,
            from,
            to,
            points,
            amplitude,
            velocity,
            periods,
            suggest,
            apply,
            json,
            out,
        } => {
            let lp = gms_bench::frf::Loop::from_name(&lp)
                .ok_or_else(|| Fail::Usage(format!("--loop {lp}: plant, open or closed")))?;
            let mut plan = gms_bench::frf::Plan::new(lp, 0.0);
            plan.from_hz = from;
            plan.to_hz = to;
            plan.points = points;
            plan.velocity = velocity;
            plan.periods = periods;
            frf::run(
                &mut link,
                &frf::Args {
                    plan,
                    amplitude,
                    out,
                    suggest,
                    apply,
                    json,
                },
            )?
        }
        Cmd::Map {
            speed,
            revs,
            bins,
            period,
            order,
            out,
            apply,
            save,
        } => map::run(
            &mut link,
            &map::Args {
                plan: gms_bench::posmap::MapPlan {
                    speed,
                    periods: revs,
                    period,
                    bins,
                    order,
                },
                out,
                apply: apply || save,
                save,
            },
        )?,
        Cmd::Learn {
            sine,
            trajectory,
            iterations,
            gain,
            q_filter,
            lead,
            out,
            apply,
        } => {
            let path = match (sine, trajectory) {
                (_, Some(file)) => {
                    let text = std::fs::read_to_string(&file)
                        .map_err(|e| Fail::Usage(format!("{}: {e}", file.display())))?;
                    gms_bench::learn::Path::Trajectory(
                        gms_bench::learn::parse_trajectory(&text)
                            .map_err(|e| Fail::Usage(format!("{}: {e}", file.display())))?,
                    )
                }
                (Some(v), None) => gms_bench::learn::Path::Sine {
                    amplitude: v.first().copied().unwrap_or(f64::NAN),
                    freq: v.get(1).copied().unwrap_or(f64::NAN),
                },
                (None, None) => gms_bench::learn::LearnPlan::default().path,
            };
            learn::run(
                &mut link,
                &learn::Args {
                    plan: gms_bench::learn::LearnPlan {
                        path,
                        iterations,
                        gain,
                        q_hz: q_filter,
                        lead_s: lead,
                        ..gms_bench::learn::LearnPlan::default()
                    },
                    out,
                    apply,
                },
            )?
        }
        #[cfg(feature = "ui")]
        Cmd::Ui { .. } => unreachable!("handled before the link opens"),
        Cmd::Identify {
            out,
            report,
            blocks,
            asymmetric,
            apply,
            save,
            ranges,
            json,
        } => identify::run(
            &mut link,
            &identify::Args {
                out,
                report,
                blocks: blocks as usize,
                asymmetric,
                apply,
                save,
                json,
                ranges,
            },
        )?,
    }
    Ok(())
}

/// One refresh of the live view: the error over the last period as a bar around zero, with
/// its extremes, and the feedforward.
fn watch(link: &mut Link, seconds: Option<f64>, refresh: Duration) -> Result<(), Fail> {
    use std::io::Write;
    let rpc = gms_bench::rad_per_count(link).map_err(|e| Fail::Device(e.to_string()))?;
    let end = seconds.map(|s| std::time::Instant::now() + Duration::from_secs_f64(s.max(0.0)));
    link.ask(Command::Stream {
        fields: "t,error,ff",
        rate_hz: 200.0,
    })?;
    println!("  t [s]   error [counts]: last   min    max   |-50 .. 0 .. +50|   ff [uN·m]");
    loop {
        link.telemetry.clear();
        link.listen(refresh)?;
        let samples: Vec<Vec<(String, f64)>> = link
            .telemetry
            .iter()
            .map(|(_, l)| parse_telemetry(l))
            .collect();
        let get = |kv: &Vec<(String, f64)>, n: &str| kv.iter().find(|(k, _)| k == n).map(|x| x.1);
        let errs: Vec<f64> = samples
            .iter()
            .filter_map(|kv| get(kv, "error"))
            .map(|e| e / rpc)
            .collect();
        if let (Some(last), Some(kv)) = (errs.last(), samples.last()) {
            let (lo, hi) = errs
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), e| (a.min(*e), b.max(*e)));
            let mut bar = [b' '; 21];
            bar[10] = b'|';
            let col = ((last / 5.0).round() as i64 + 10).clamp(0, 20) as usize;
            bar[col] = b'*';
            print!(
                "\r\x1b[K{:8.3}   {:6.1} {:6.1} {:6.1}   {}   {:8.2}",
                get(kv, "t").unwrap_or(0.0),
                last,
                lo,
                hi,
                String::from_utf8_lossy(&bar),
                get(kv, "ff").unwrap_or(0.0) * 1e6
            );
            let _ = std::io::stdout().flush();
        }
        if end.is_some_and(|e| std::time::Instant::now() >= e) {
            println!();
            link.ask(Command::StreamOff)?;
            return Ok(());
        }
    }
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(Fail::Device(e)) => {
            eprintln!("error: {e}");
            ExitCode::from(1)
        }
        Err(Fail::Usage(e)) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}
