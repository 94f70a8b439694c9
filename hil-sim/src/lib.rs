//! # hil-sim
//!
//! The simulator's command (`hil-sim`): the simulated axis of [`gms_sim`] (re-exported here
//! whole), and the bench's workflows of `gms-bench` run on its virtual device
//! (`hil-sim experiment --rig device`, `hil-sim learn`). The simulator itself does not depend
//! on the bench crate: the two meet at `gms_link::DeviceLink`.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub use gms_sim::*;

pub mod bench;
pub mod learn;
