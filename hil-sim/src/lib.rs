//! # hil-sim
//!
//! The simulated axis: the plant (motor, gearhead, lead screw, guideways, sensors), scenarios,
//! closed-loop runs of gms-core's controller against it, the paper's experiments on it, and
//! the virtual device (gms-core's device core on the plant, `hil-sim serve`). The fits and
//! the parameter file are `gms-ident`'s; the bench tool is `gms-tune`.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod commands;
pub mod device;
pub mod experiment;
pub mod friction_cmd;
pub mod plant;
pub mod scenario;
pub mod sim;
