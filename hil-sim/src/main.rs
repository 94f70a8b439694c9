//! `hil-sim`: the gms simulator and tools.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use hil_sim::friction_cmd;

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
        /// Trajectory CSV with a header naming at least `t` [s] and `x` [m or rad].
        #[arg(long, value_name = "TRAJ.csv")]
        input: PathBuf,
        /// Output CSV: t,x,v,f (written atomically).
        #[arg(long, value_name = "OUT.csv")]
        output: PathBuf,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.cmd {
        Cmd::Friction {
            params,
            input,
            output,
        } => match friction_cmd::run(&params, &input, &output) {
            Ok((_, warnings)) => {
                for w in warnings {
                    eprintln!("warning: {w}");
                }
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(2)
            }
        },
    }
}
