//! The device's tables over the protocol: the status, the reference and the correction
//! written, the tables read.

use super::*;

/// The device's `table` status.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TableStatus {
    /// `empty`, `ready` or `playing` (`none`: no table motion on this device).
    pub playing: bool,
    /// A reference is set.
    pub ready: bool,
    /// Periods completed in the run.
    pub period: u32,
    /// The correction's generation played.
    pub generation: u32,
    /// A correction waits for the next period's start.
    pub pending: bool,
    /// The position step the run started at.
    pub started: u64,
    /// The last complete period: its number, its correction's generation, RMS and peak
    /// \[counts\].
    pub done: Option<(u32, u32, f64, f64)>,
    /// That period is held: the periods after it do not replace it until `table next` or a
    /// new correction.
    pub held: bool,
}

impl From<TableReport> for TableStatus {
    fn from(t: TableReport) -> TableStatus {
        TableStatus {
            playing: t.state == TableState::Playing,
            ready: t.state != TableState::Empty,
            period: t.period,
            generation: t.generation,
            pending: t.pending,
            started: t.started,
            done: t
                .done
                .map(|d| (d.period, d.generation, f64::from(d.rms), f64::from(d.peak))),
            held: t.held,
        }
    }
}

/// Reads the device's `table` status ([`protocol::TableStatus::parse`]: the device core's own
/// format).
pub fn table_status(b: &mut impl Bench) -> Result<TableStatus, Error> {
    let (_, text) = b.send(Command::Table(TableCmd::Status))?;
    match protocol::TableStatus::parse(&text) {
        Ok(protocol::TableStatus(Some(t))) => Ok(t.into()),
        Ok(protocol::TableStatus(None)) => {
            Err(Error::Device("the device has no table motion".into()))
        }
        Err(e) => Err(Error::Device(format!("{e}: {text}"))),
    }
}

/// Writes `values` to the device's table `which` (`ref` or `corr`), as many a line as the
/// protocol's line carries (eight at most).
pub(super) fn write_values(b: &mut impl Bench, which: Which, values: &[f64]) -> Result<(), Error> {
    let max_line = gms_core::protocol::MAX_LINE - 1;
    let mut at = 0;
    while at < values.len() {
        let start = at as u32;
        // The line's length without its values (`table ref START`).
        let head = Command::Table(TableCmd::Write {
            which,
            start,
            values: "",
        })
        .to_string()
        .len();
        let mut text = String::new();
        let mut n = 0;
        while let Some(v) = values.get(at + n) {
            // f32's shortest decimal: the device reads back the same value.
            let word = format!("{}", *v as f32);
            let sep = usize::from(!text.is_empty());
            if n == gms_core::control::table::TABLE_WRITE_VALUES
                || head + text.len() + sep + word.len() > max_line
            {
                break;
            }
            if sep == 1 {
                text.push(' ');
            }
            text.push_str(&word);
            n += 1;
        }
        b.send(Command::Table(TableCmd::Write {
            which,
            start,
            values: &text,
        }))?;
        at += n.max(1);
    }
    Ok(())
}

/// Uploads the reference and sets it (the device checks it whole: continuous, within the
/// speed limit and the soft limits; nothing moves if it refuses).
pub fn set_table(b: &mut impl Bench, t: &Table) -> Result<(), Error> {
    write_values(b, Which::Ref, &t.values)?;
    let g = Geometry {
        points: t.points,
        steps: t.steps,
        origin: t.origin,
    };
    b.send(Command::Table(TableCmd::Set(g))).map(drop)
}

/// Uploads a correction \[N·m at the points\] and has it played from the next period's start.
pub fn use_correction(b: &mut impl Bench, u: &[f64]) -> Result<(), Error> {
    write_values(b, Which::Corr, u)?;
    b.send(Command::Table(TableCmd::Use)).map(drop)
}

/// Reads `n` values of the device's table `which` (`ref`, `corr` or `err`).
pub fn read_values(b: &mut impl Bench, which: Which, n: u32) -> Result<Vec<f64>, Error> {
    let rows = crate::client::read_rows(b, n, "table", |start, count| {
        Command::Table(TableCmd::Read {
            which,
            start,
            count,
        })
    })?;
    rows.iter()
        .map(|r| match r.as_slice() {
            [v] => Ok(*v),
            _ => Err(Error::Device(format!("bad table line: {r:?}"))),
        })
        .collect()
}
