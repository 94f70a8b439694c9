//! # gms-ident
//!
//! Friction identification and trace analysis on data, for the host: the paper's fits (the
//! virgin curve of pre-sliding, the Stribeck curve of sliding, the frictional lag) on arrays,
//! the parameter file they produce, a run's figures and plots. Used by the simulator
//! (`hil-sim`) and by the bench tool (`gms-tune`), so that a simulated and a measured
//! experiment go through the same code.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod identify;
pub mod io;
pub mod paramfile;
pub mod plot;
pub mod trace;
