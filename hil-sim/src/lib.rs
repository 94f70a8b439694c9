//! # hil-sim
//!
//! The host side of gms: the simulator of the positioning axis and its command-line tools,
//! reusing `gms-core` unchanged. Today: the parameter file ([`paramfile`]) and the friction
//! command ([`friction_cmd`]).
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod commands;
pub mod device;
pub mod experiment;
pub mod friction_cmd;
pub mod identify;
pub mod paramfile;
pub mod plant;
pub mod plot;
pub mod scenario;
pub mod sim;
pub mod tune;
