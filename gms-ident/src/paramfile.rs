//! The parameter file (TOML), shared by the simulator, the identification and the bench tool.
//!
//! ```toml
//! [friction]
//! model = "gms"          # "gms" (default), "lugre" or "static"
//! fs = 220e-6            # static friction [N or N·m]
//! fc = 125e-6            # Coulomb friction [N or N·m]
//! vs = 0.2               # Stribeck velocity [m/s or rad/s]
//! delta = 0.9            # Stribeck shape factor [-] (default 1, the paper's eq. 1)
//! sigma = 10.5e-6        # viscous coefficient [N·s/m or N·m·s/rad] (default 0)
//! c = 5e-3               # GMS attraction parameter [N/s or N·m/s]
//! blocks = [{ k = 1.159, alpha = 0.575 }, …]   # GMS blocks: k [N/m or N·m/rad], alpha [-]
//! # sigma0 = 1e5         # LuGre bristle stiffness [N/m or N·m/rad]
//! # sigma1 = 300         # LuGre bristle damping [N·s/m or N·m·s/rad] (default 0)
//!
//! [friction.negative]    # optional: fs, fc, vs, delta for v < 0 (each defaults to the above)
//! fs = 240e-6
//! ```
//! Units are SI and consistent (translational N, m or rotational N·m, rad; s). Unknown keys
//! are errors; keys that the chosen model does not use are reported as warnings.

use crate::Error;
use std::fmt;
use std::path::Path;

use gms_core::{
    Block, FrictionModel, Gms, GmsParams, LuGre, LugreParams, StaticMap, StaticParams,
    StribeckParams,
};
use serde::{Deserialize, Serialize};

/// The largest number of GMS blocks a parameter file may have.
pub const MAX_BLOCKS: usize = 32;

/// A whole parameter file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParamFile {
    /// The `[friction]` table.
    pub friction: FrictionSpec,
    /// Optional `[device]` table: other device settings by protocol path (`gms-tune params`);
    /// not used by the friction command.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device: Option<toml::Table>,
}

/// Which friction model a `[friction]` table describes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelKind {
    /// Generalized Maxwell-Slip (the default).
    #[default]
    Gms,
    /// LuGre.
    Lugre,
    /// Static map: Stribeck + Coulomb + viscous.
    Static,
}

impl fmt::Display for ModelKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ModelKind::Gms => "gms",
            ModelKind::Lugre => "lugre",
            ModelKind::Static => "static",
        })
    }
}

/// One GMS block as written in the file.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BlockSpec {
    /// Stiffness [N/m or N·m/rad].
    pub k: f64,
    /// Weight [-].
    pub alpha: f64,
}

/// The optional `[friction.negative]` table: Stribeck parameters for v < 0.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NegativeSpec {
    /// Static friction for v < 0 [N or N·m].
    pub fs: Option<f64>,
    /// Coulomb friction for v < 0 [N or N·m].
    pub fc: Option<f64>,
    /// Stribeck velocity for v < 0 [m/s or rad/s].
    pub vs: Option<f64>,
    /// Shape factor for v < 0 [-].
    pub delta: Option<f64>,
}

/// The `[friction]` table as written (every key optional until the model is built).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrictionSpec {
    /// The model; "gms" when absent.
    #[serde(default)]
    pub model: ModelKind,
    /// Static friction [N or N·m].
    pub fs: Option<f64>,
    /// Coulomb friction [N or N·m].
    pub fc: Option<f64>,
    /// Stribeck velocity [m/s or rad/s].
    pub vs: Option<f64>,
    /// Stribeck shape factor [-]; 1 when absent.
    pub delta: Option<f64>,
    /// Viscous coefficient [N·s/m or N·m·s/rad]; 0 when absent.
    pub sigma: Option<f64>,
    /// GMS attraction parameter [N/s or N·m/s].
    pub c: Option<f64>,
    /// GMS blocks.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub blocks: Option<Vec<BlockSpec>>,
    /// LuGre bristle stiffness [N/m or N·m/rad].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma0: Option<f64>,
    /// LuGre bristle damping [N·s/m or N·m·s/rad]; 0 when absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma1: Option<f64>,
    /// Stribeck parameters for v < 0.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub negative: Option<NegativeSpec>,
}

/// A friction model of any kind and block count, ready to run.
pub type AnyModel = Box<dyn FrictionModel + Send>;

/// An error in a parameter file, one line: `FILE[:LINE:COL]: reason`.
#[derive(Debug, Clone, PartialEq)]
pub struct FileError {
    /// The file, as given.
    pub file: String,
    /// 1-based line and column, when known.
    pub at: Option<(usize, usize)>,
    /// What is wrong, naming the key.
    pub reason: String,
}

impl fmt::Display for FileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.at {
            Some((l, c)) => write!(f, "{}:{l}:{c}: {}", self.file, self.reason),
            None => write!(f, "{}: {}", self.file, self.reason),
        }
    }
}

impl std::error::Error for FileError {}

/// 1-based line and column of byte offset `pos` in `text`.
pub fn line_col(text: &str, pos: usize) -> (usize, usize) {
    let before = &text[..pos.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

/// Reads a text file; returns its name (as given) and text, or a one-line error.
pub fn read_text(path: &Path) -> Result<(String, String), FileError> {
    let file = path.display().to_string();
    match std::fs::read_to_string(path) {
        Ok(text) => Ok((file, text)),
        Err(e) => Err(FileError {
            file,
            at: None,
            reason: format!("cannot read: {e}"),
        }),
    }
}

/// Parses TOML `text` of `file` into `T`; a syntax or type error becomes one line with its
/// position.
pub fn parse_toml<T: serde::de::DeserializeOwned>(text: &str, file: &str) -> Result<T, FileError> {
    toml::from_str(text).map_err(|e| FileError {
        file: file.to_string(),
        at: e.span().map(|s| line_col(text, s.start)),
        reason: e.message().replace('\n', " ").trim().to_string(),
    })
}

impl ParamFile {
    /// Reads and parses `path` (no model is built yet).
    pub fn load(path: &Path) -> Result<ParamFile, FileError> {
        let (file, text) = read_text(path)?;
        Self::parse(&text, &file)
    }

    /// Parses the text of a parameter file; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<ParamFile, FileError> {
        parse_toml(text, file)
    }

    /// The file's text.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }
}

/// A required key, or an error naming it.
fn need(v: Option<f64>, key: &str, model: ModelKind) -> Result<f64, String> {
    v.ok_or_else(|| format!("[friction] needs `{key}` for model {model}"))
}

impl FrictionSpec {
    /// Keys present in the table that `self.model` does not use.
    pub fn unused_keys(&self) -> Vec<&'static str> {
        let mut out = Vec::new();
        let gms = self.model == ModelKind::Gms;
        let lugre = self.model == ModelKind::Lugre;
        if !gms && self.c.is_some() {
            out.push("c");
        }
        if !gms && self.blocks.is_some() {
            out.push("blocks");
        }
        if !lugre && self.sigma0.is_some() {
            out.push("sigma0");
        }
        if !lugre && self.sigma1.is_some() {
            out.push("sigma1");
        }
        out
    }

    /// The positive (or symmetric) and the optional negative Stribeck parameters.
    fn stribeck(&self) -> Result<(StribeckParams, Option<StribeckParams>), String> {
        let pos = StribeckParams {
            fs: need(self.fs, "fs", self.model)? as f32,
            fc: need(self.fc, "fc", self.model)? as f32,
            vs: need(self.vs, "vs", self.model)? as f32,
            delta: self.delta.unwrap_or(1.0) as f32,
        };
        let neg = self.negative.map(|n| StribeckParams {
            fs: n.fs.map_or(pos.fs, |v| v as f32),
            fc: n.fc.map_or(pos.fc, |v| v as f32),
            vs: n.vs.map_or(pos.vs, |v| v as f32),
            delta: n.delta.map_or(pos.delta, |v| v as f32),
        });
        Ok((pos, neg))
    }

    /// The GMS parameters in a set of `N` blocks (unvalidated), or why not: a table with
    /// fewer blocks fills the first ones and leaves the rest unused (`k = alpha = 0`).
    pub fn gms_params<const N: usize>(&self) -> Result<GmsParams<N>, Error> {
        self.gms_params_inner::<N>().map_err(Error::Params)
    }

    fn gms_params_inner<const N: usize>(&self) -> Result<GmsParams<N>, String> {
        let (stribeck, negative) = self.stribeck()?;
        let blocks = self.blocks.as_deref().unwrap_or(&[]);
        if blocks.len() > N {
            return Err(format!(
                "[friction] has {} blocks, at most {N} fit",
                blocks.len()
            ));
        }
        Ok(GmsParams {
            stribeck,
            negative,
            sigma: self.sigma.unwrap_or(0.0) as f32,
            c: need(self.c, "c", self.model)? as f32,
            blocks: core::array::from_fn(|i| {
                blocks.get(i).map_or(gms_core::UNUSED_BLOCK, |b| Block {
                    k: b.k as f32,
                    alpha: b.alpha as f32,
                })
            }),
        })
    }

    /// The quasi-static virgin curve of its GMS blocks at displacement `x` \[m or rad\]:
    /// Σ min(k_i x, alpha_i Fs) \[N or N·m\] (paper eq. 3; 0 without blocks or fs).
    pub fn virgin(&self, x: f64) -> f64 {
        let fs = self.fs.unwrap_or(0.0);
        self.blocks
            .iter()
            .flatten()
            .map(|b| (b.k * x).min(b.alpha * fs))
            .sum()
    }

    /// The end of the pre-sliding range: the largest block breakpoint alpha_i Fs / k_i
    /// [m or rad] (0 without blocks or fs).
    pub fn largest_breakpoint(&self) -> f64 {
        let fs = self.fs.unwrap_or(0.0);
        self.blocks
            .iter()
            .flatten()
            .map(|b| b.alpha * fs / b.k)
            .fold(0.0, f64::max)
    }

    /// Builds and validates the model; the error names the offending key.
    pub fn build(&self) -> Result<AnyModel, Error> {
        self.build_inner().map_err(Error::Params)
    }

    fn build_inner(&self) -> Result<AnyModel, String> {
        let invalid = |e: gms_core::ParamError| format!("[friction] {e}");
        match self.model {
            ModelKind::Gms => {
                let n = self.blocks.as_ref().map_or(0, Vec::len);
                if n == 0 {
                    return Err("[friction] needs `blocks` (at least one) for model gms".into());
                }
                build_gms(self, n)
            }
            ModelKind::Lugre => {
                let (stribeck, negative) = self.stribeck()?;
                let p = LugreParams {
                    stribeck,
                    negative,
                    sigma0: need(self.sigma0, "sigma0", self.model)? as f32,
                    sigma1: self.sigma1.unwrap_or(0.0) as f32,
                    sigma: self.sigma.unwrap_or(0.0) as f32,
                };
                Ok(Box::new(LuGre::try_new(p).map_err(invalid)?))
            }
            ModelKind::Static => {
                let (stribeck, negative) = self.stribeck()?;
                let p = StaticParams {
                    stribeck,
                    negative,
                    sigma: self.sigma.unwrap_or(0.0) as f32,
                };
                Ok(Box::new(StaticMap::try_new(p).map_err(invalid)?))
            }
        }
    }

    /// The table of a GMS parameter set (its blocks in use).
    pub fn from_gms<const N: usize>(p: &GmsParams<N>) -> FrictionSpec {
        FrictionSpec {
            model: ModelKind::Gms,
            fs: Some(p.stribeck.fs as f64),
            fc: Some(p.stribeck.fc as f64),
            vs: Some(p.stribeck.vs as f64),
            delta: Some(p.stribeck.delta as f64),
            sigma: Some(p.sigma as f64),
            c: Some(p.c as f64),
            blocks: Some(
                p.blocks
                    .iter()
                    .take(p.blocks_used())
                    .map(|b| BlockSpec {
                        k: b.k as f64,
                        alpha: b.alpha as f64,
                    })
                    .collect(),
            ),
            negative: p.negative.map(|n| NegativeSpec {
                fs: Some(n.fs as f64),
                fc: Some(n.fc as f64),
                vs: Some(n.vs as f64),
                delta: Some(n.delta as f64),
            }),
            ..FrictionSpec::default()
        }
    }
}

/// A GMS model with `N` blocks, boxed.
fn gms_boxed<const N: usize>(spec: &FrictionSpec) -> Result<AnyModel, String> {
    let p = spec.gms_params::<N>()?;
    Ok(Box::new(
        Gms::try_new(p).map_err(|e| format!("[friction] {e}"))?,
    ))
}

/// Dispatches the block count `n` (1..=MAX_BLOCKS) to the const-generic model.
fn build_gms(spec: &FrictionSpec, n: usize) -> Result<AnyModel, String> {
    macro_rules! by_count {
        ($($n:literal)*) => {
            match n {
                $($n => gms_boxed::<$n>(spec),)*
                _ => Err(format!("[friction] has {n} blocks, at most {MAX_BLOCKS} are supported")),
            }
        };
    }
    by_count!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24 25 26 27 28 29 30 31 32)
}
