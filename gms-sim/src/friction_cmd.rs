//! `hil-sim friction`: a friction model driven by a position trajectory from a CSV file.
//!
//! Input: a header naming at least `t` \[s\] and `x` [m or rad] (any order, other columns
//! ignored), one sample per row, `t` strictly increasing, every value finite. Between two rows
//! the motion is at constant velocity. Output: `t,x,v,f`, one row per input row, `v` the
//! velocity of the motion that ended at this row and `f` the friction after it (row 0: the
//! virgin state at rest, `v = f = 0`).

use crate::Error;
use std::io::Write;
use std::path::Path;

use gms_ident::paramfile::{AnyModel, FileError, ParamFile};

/// One sample of a trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrajectoryPoint {
    /// Time \[s\].
    pub t: f64,
    /// Position [m or rad].
    pub x: f64,
}

/// One row of the output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrictionRow {
    /// Time \[s\].
    pub t: f64,
    /// Position [m or rad].
    pub x: f64,
    /// Velocity of the motion from the previous row [m/s or rad/s].
    pub v: f64,
    /// Friction after that motion [N or N·m].
    pub f: f32,
}

/// Reads a trajectory CSV (see the module docs); errors name the file, line and column.
pub fn read_trajectory(path: &Path) -> Result<Vec<TrajectoryPoint>, FileError> {
    let file = path.display().to_string();
    let err = |line: Option<u64>, reason: String| FileError {
        file: file.clone(),
        at: line.map(|l| (l as usize, 1)),
        reason,
    };
    let mut rdr = csv::ReaderBuilder::new()
        .flexible(true)
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| err(None, format!("cannot read: {}", io_reason(&e))))?;
    let headers = rdr
        .headers()
        .map_err(|e| err(Some(1), format!("bad header: {}", io_reason(&e))))?
        .clone();
    let col = |name: &str| {
        headers
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| err(Some(1), format!("the header has no `{name}` column")))
    };
    let (ti, xi) = (col("t")?, col("x")?);
    let mut out: Vec<TrajectoryPoint> = Vec::new();
    let mut rec = csv::StringRecord::new();
    loop {
        match rdr.read_record(&mut rec) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => {
                let line = e.position().map(|p| p.line());
                return Err(err(line, format!("unreadable row: {}", io_reason(&e))));
            }
        }
        let line = rec.position().map(|p| p.line());
        if rec.len() != headers.len() {
            return Err(err(
                line,
                format!(
                    "row has {} fields, the header has {}",
                    rec.len(),
                    headers.len()
                ),
            ));
        }
        let num = |i: usize, name: &str| -> Result<f64, FileError> {
            let s = &rec[i];
            let v: f64 = s
                .parse()
                .map_err(|_| err(line, format!("`{name}` is not a number: {s:?}")))?;
            if !v.is_finite() {
                return Err(err(line, format!("`{name}` is not finite: {s}")));
            }
            Ok(v)
        };
        let s = TrajectoryPoint {
            t: num(ti, "t")?,
            x: num(xi, "x")?,
        };
        if let Some(prev) = out.last() {
            // Both are finite here.
            if s.t <= prev.t {
                return Err(err(
                    line,
                    format!("t does not increase: {} after {}", s.t, prev.t),
                ));
            }
        }
        out.push(s);
    }
    Ok(out)
}

/// The reason of a csv error without its position prefix.
fn io_reason(e: &csv::Error) -> String {
    match e.kind() {
        csv::ErrorKind::Io(io) => io.to_string(),
        csv::ErrorKind::Utf8 { err, .. } => format!("invalid UTF-8: {err}"),
        _ => e.to_string(),
    }
}

/// Drives `model` (from its current state) through `traj`.
pub fn simulate(model: &mut AnyModel, traj: &[TrajectoryPoint]) -> Vec<FrictionRow> {
    let mut out = Vec::with_capacity(traj.len());
    let mut prev: Option<TrajectoryPoint> = None;
    for &s in traj {
        let (v, f) = match prev {
            None => (0.0, model.force()),
            Some(p) => {
                let (dx, dt) = (s.x - p.x, s.t - p.t);
                (dx / dt, model.advance(dx as f32, dt as f32))
            }
        };
        out.push(FrictionRow {
            t: s.t,
            x: s.x,
            v,
            f,
        });
        prev = Some(s);
    }
    out
}

/// Writes `rows` as `t,x,v,f` to `path` atomically: a temporary file in the same directory,
/// renamed over `path` once complete.
pub fn write_rows(path: &Path, rows: &[FrictionRow]) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut tmp = tempfile::NamedTempFile::new_in(dir)?;
    {
        let mut w = std::io::BufWriter::new(tmp.as_file_mut());
        writeln!(w, "t,x,v,f")?;
        for r in rows {
            // f as the f64 of its exact f32 value: read back as f64 by any reader, the same
            // number the model computed (the shortest f32 text is not, as f64).
            writeln!(w, "{},{},{},{}", r.t, r.x, r.v, r.f as f64)?;
        }
        w.flush()?;
    }
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// Runs the whole command; returns the number of rows written and the warnings, or one line
/// that names the file (and line or key) and the reason. Nothing is written on error.
pub fn run(params: &Path, input: &Path, output: &Path) -> Result<(usize, Vec<String>), Error> {
    run_inner(params, input, output).map_err(Error::Run)
}

fn run_inner(params: &Path, input: &Path, output: &Path) -> Result<(usize, Vec<String>), String> {
    let pf = ParamFile::load(params).map_err(|e| e.to_string())?;
    let mut model = pf
        .friction
        .build()
        .map_err(|e| format!("{}: {e}", params.display()))?;
    let warnings = pf
        .friction
        .unused_keys()
        .iter()
        .map(|k| {
            format!(
                "{}: [friction] `{k}` is not used by model {}",
                params.display(),
                pf.friction.model
            )
        })
        .collect();
    let traj = read_trajectory(input).map_err(|e| e.to_string())?;
    let rows = simulate(&mut model, &traj);
    write_rows(output, &rows).map_err(|e| format!("{}: cannot write: {e}", output.display()))?;
    Ok((rows.len(), warnings))
}
