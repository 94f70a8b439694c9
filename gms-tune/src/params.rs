//! The device's parameters as a parameter file, and a file sent back as one set: shared by
//! `gms-tune params dump/load`, `commission`, `identify` and the window.

use gms_core::protocol::{Command, ListRange, ListRow};
use std::path::Path;

use gms_ident::paramfile::ParamFile;

use crate::{Link, LinkError};

/// One row of `list`: a parameter's path, value, unit and range (as the device prints them).
#[derive(Debug, Clone, PartialEq)]
pub struct Listed {
    /// Protocol path (`pos.kp`).
    pub path: String,
    /// The device's value, as printed.
    pub value: String,
    /// The value as a number, where it is one.
    pub number: Option<f64>,
    /// Unit (`-` for none).
    pub unit: String,
    /// The range as printed (`[0, 1000]`, `[none, static, gms, gms-adaptive]`, `[read-only]`).
    pub range: String,
    /// An estimate: the device refuses sets of it.
    estimate: bool,
}

impl Listed {
    /// Whether the device refuses sets of it (an estimate).
    pub fn read_only(&self) -> bool {
        self.estimate
    }
}

impl From<&ListRow<'_>> for Listed {
    fn from(r: &ListRow<'_>) -> Listed {
        Listed {
            path: r.path.to_string(),
            value: r.value.to_string(),
            number: r.value.number().map(f64::from),
            unit: r.unit.to_string(),
            range: r.range.to_string(),
            estimate: r.range == ListRange::ReadOnly,
        }
    }
}

/// Parses one line of `list` ([`ListRow::parse`]: `path value unit [range]`).
pub fn parse_list_line(line: &str) -> Option<Listed> {
    ListRow::parse(line).ok().map(|r| Listed::from(&r))
}

/// Every parameter `list` prints, read-only estimates included.
pub fn list(link: &mut Link) -> Result<Vec<Listed>, LinkError> {
    let (lines, _) = link.ask(Command::List)?;
    lines
        .iter()
        .map(|l| {
            ListRow::parse(l)
                .map(|r| Listed::from(&r))
                .map_err(|e| LinkError::Reply(format!("{e}: {l}")))
        })
        .collect()
}

/// The device's parameters as a parameter file: `[friction]` (the compensator's GMS model)
/// and `[device]` (everything else settable, by protocol path) ([`gms_bench::paramfile`]).
pub fn read(link: &mut Link) -> Result<ParamFile, LinkError> {
    gms_bench::paramfile::dump(link).map_err(LinkError::Bench)
}

/// The parameter file of a `list` (read-only estimates left out): the rows read into the
/// device core's settings, then [`gms_bench::paramfile::file_of`].
pub fn to_file(listed: &[Listed]) -> Result<ParamFile, String> {
    let mut s = gms_core::device::default_settings();
    for p in listed {
        s = gms_bench::settings::with_listed(&s, &p.path, &p.value).map_err(|e| e.to_string())?;
    }
    Ok(gms_bench::paramfile::file_of(&s))
}

/// Why a parameter file was not loaded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LoadError {
    /// The file cannot be read or is not a valid set (the message names it).
    File(String),
    /// The device refused it or the link failed.
    Device(String),
}

impl std::fmt::Display for LoadError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LoadError::File(m) | LoadError::Device(m) => f.write_str(m),
        }
    }
}

/// Sends the parameter file `file` as one set (`gms_bench::load_params`); returns the
/// number of parameters sent.
pub fn load(link: &mut Link, file: &Path) -> Result<usize, LoadError> {
    let pf = ParamFile::load(file).map_err(|e| LoadError::File(e.to_string()))?;
    gms_bench::load_params(link, &pf).map_err(|e| match e {
        gms_bench::Error::Params(m) => LoadError::File(format!("{}: {m}", file.display())),
        e => LoadError::Device(e.to_string()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn list_lines_parse() {
        let n = parse_list_line("pos.kp 0.2 N·m/rad [0, 1000]").unwrap();
        assert_eq!(
            (
                n.path.as_str(),
                n.value.as_str(),
                n.unit.as_str(),
                n.range.as_str()
            ),
            ("pos.kp", "0.2", "N·m/rad", "[0, 1000]")
        );
        let m = parse_list_line("ff.mode gms - [none, static, gms, gms-adaptive]").unwrap();
        assert_eq!((m.value.as_str(), m.unit.as_str()), ("gms", "-"));
        let e = parse_list_line("ff.scale 1 - [read-only]").unwrap();
        assert!(e.read_only());
        assert!(parse_list_line("lonely").is_none());
    }
}
