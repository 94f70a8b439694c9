//! The device's settings as one typed value on the host: read whole with `list` into the
//! device core's own [`Settings`] (the protocol's parameter table is the one mapping between
//! paths and fields), written as one staged set (`stage` … `commit`: all or nothing on the
//! device), and a snapshot that puts them back around a run ([`restoring`]), like a vendor's
//! configuration snapshot around a calibration.

use crate::Error;
use gms_core::protocol::{self, Access, Command, ErrorCode, PARAMS, Settings};

use crate::client::Bench;

/// The device's settings, read with `list`. Parameters the host does not know (a newer
/// firmware's) are skipped; parameters the device does not list (an older firmware's) keep
/// their built-in defaults, so they never differ between two reads.
pub fn read(b: &mut impl Bench) -> Result<Settings, Error> {
    let (lines, _) = b.send_to_end(Command::List)?;
    parse_list(&lines)
}

/// The settings in `list`'s reply lines ([`protocol::ListRow::parse`]: `PATH VALUE UNIT
/// [RANGE]`).
pub fn parse_list(lines: &[String]) -> Result<Settings, Error> {
    let mut s = gms_core::device::default_settings();
    for line in lines {
        let row =
            protocol::ListRow::parse(line).map_err(|e| Error::Device(format!("{e}: {line}")))?;
        s = with_listed(&s, row.path, &row.value.to_string())?;
    }
    Ok(s)
}

/// `s` with one listed parameter's value (its text as `list` prints it) set; an estimate, or
/// a parameter the host does not know (a newer firmware's), leaves it as it is.
pub fn with_listed(s: &Settings, path: &str, value: &str) -> Result<Settings, Error> {
    match protocol::find(path).map(|p| p.access) {
        None | Some(Access::Estimate(_)) => return Ok(*s),
        Some(_) => {}
    }
    protocol::with_value_staged(s, path, value)
        .map_err(|e| Error::Device(format!("the list's {path} {value}: {}", e.reason)))
}

/// The parameters whose values differ between `from` and `to`, as `(path, value of to)`, in
/// the table's order (values as the device writes them, so they read back exactly).
pub fn changes(from: &Settings, to: &Settings) -> Vec<(&'static str, String)> {
    PARAMS
        .iter()
        .filter(|p| !matches!(p.access, Access::Estimate(_)))
        .filter_map(|p| {
            let (mut a, mut b) = (String::new(), String::new());
            let _ = protocol::write_value(p, from, &mut a);
            let _ = protocol::write_value(p, to, &mut b);
            (a != b).then_some((p.path, b))
        })
        .collect()
}

/// Makes the device's settings `to`: reads them, then sends every difference as one set
/// ([`apply`]). Returns how many parameters changed. Goes out even after a run was stopped
/// ([`Bench::send_to_end`]).
pub fn write(b: &mut impl Bench, to: &Settings) -> Result<usize, Error> {
    let now = read(b)?;
    let diff: Vec<(String, String)> = changes(&now, to)
        .into_iter()
        .map(|(p, v)| (p.to_string(), v))
        .collect();
    if diff.is_empty() {
        return Ok(0);
    }
    apply(b, &diff, true)
}

/// Sends `sets` (path, value as text) as one set: staged and committed (all or nothing: on a
/// refusal the staging is discarded and nothing changes), or, on a firmware without staging,
/// one `set` at a time, retried while any goes in (a set may be refused while others are
/// pending: Fs below the old Fc, say). `to_end`: the requests go out even after a run was
/// stopped. Returns how many were sent.
pub fn apply(b: &mut impl Bench, sets: &[(String, String)], to_end: bool) -> Result<usize, Error> {
    let send = |b: &mut _, c: Command<'_>| {
        if to_end {
            Bench::send_to_end(b, c)
        } else {
            Bench::send(b, c)
        }
    };
    match send(b, Command::Discard) {
        Ok(_) => {
            for (k, v) in sets {
                if let Err(e) = send(b, Command::Stage(k, v)) {
                    let _ = send(b, Command::Discard);
                    return Err(Error::Device(format!(
                        "stage {k} {v}: {e} (nothing changed)"
                    )));
                }
            }
            send(b, Command::Commit)
                .map_err(|e| Error::Device(format!("commit: {e} (nothing changed)")))?;
            return Ok(sets.len());
        }
        // A firmware without staging: one `set` at a time.
        Err(e) if e.refused_with(ErrorCode::UnknownCommand) => {}
        Err(e) => return Err(e),
    }
    let mut left: Vec<&(String, String)> = sets.iter().collect();
    let mut last_err = String::new();
    while !left.is_empty() {
        let before = left.len();
        let mut rest = Vec::new();
        for kv in left {
            match send(b, Command::Set(&kv.0, &kv.1)) {
                Ok(_) => {}
                Err(e @ Error::Refused(_)) => {
                    last_err = format!("set {} {}: {e}", kv.0, kv.1);
                    rest.push(kv);
                }
                Err(e) => return Err(e),
            }
        }
        if rest.len() == before {
            return Err(Error::Device(last_err));
        }
        left = rest;
    }
    Ok(sets.len())
}

/// The device's settings before a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Snapshot {
    settings: Settings,
}

impl Snapshot {
    /// Reads the device's settings.
    pub fn take(b: &mut impl Bench) -> Result<Snapshot, Error> {
        Ok(Snapshot { settings: read(b)? })
    }

    /// The settings as they were.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Switches the bridge off and puts the settings back as they were (one staged set);
    /// returns how many parameters it put back.
    pub fn restore(&self, b: &mut impl Bench) -> Result<usize, Error> {
        b.send_to_end(Command::Disable)?;
        write(b, &self.settings)
    }
}

/// Runs `f` between a snapshot of the device's settings and their restoration: whatever `f`
/// changed (stroke limits, gains, directions, the feedforward gain), and however it ended
/// (done, failed, stopped), the bridge is off and the settings are back after it. The run's
/// error comes first; a restoration that fails too is added to it (or is the error of a run
/// that succeeded). Results a run should leave on the device are applied after this.
pub fn restoring<B: Bench, T>(
    b: &mut B,
    f: impl FnOnce(&mut B) -> Result<T, Error>,
) -> Result<T, Error> {
    let snap = Snapshot::take(b)?;
    let r = f(b);
    let back = snap.restore(b);
    match (r, back) {
        (Ok(v), Ok(_)) => Ok(v),
        (Ok(_), Err(e)) => Err(Error::Device(format!(
            "the run ended, but the settings could not be put back: {e}"
        ))),
        (Err(e), Ok(_)) => Err(e),
        (Err(e), Err(back)) => {
            Err(e.with_note(&format!("the settings could not be put back: {back}")))
        }
    }
}
