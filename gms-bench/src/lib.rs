//! # gms-bench
//!
//! The bench workflows, written once against an abstract bench ([`Bench`]): anything that
//! answers the bench protocol — a board over USB or UART, the virtual device over TCP
//! (`gms-tune`'s link), the device core in-process on the simulated plant (`hil-sim`'s
//! `LocalDevice`). A workflow only sends protocol requests and lets device time pass, so it
//! runs alike on all of them; the fits it ends with are `gms-ident`'s, on arrays.
//!
//! - [`client`]: the bench and its primitives (parameters, `status`, capture, moves, the
//!   bridge off on failure).
//! - [`experiments`]: the paper's sliding, pre-sliding and frictional-lag runs, their plans.
//! - [`frf`](mod@frf): frequency response — the stepped-sine sweep of the device's own
//!   measurement, the transfer functions, the margins, the pre-sliding stiffness.
//! - [`ilc`]: iterative learning control's law (a gain with a lead, a zero-phase Q filter, the
//!   iterations kept and divergence stopped), for the repeated motions of issue 30.
//! - [`learn`]: learning from repetition on a device — the table motion's path, upload and
//!   error reads, the iterations.
//! - [`identify`]: the whole identification on a device, loading a parameter file.
//! - [`paramfile`]: the parameter file ↔ the device's settings, in one place.
//! - [`posmap`]: the position map measured — runs both ways, a harmonic fit, the cogging
//!   (direction-even) and the friction's scale (direction-odd) at each angle.
//! - [`settings`]: the device's settings as one typed value, and the snapshot that puts them
//!   back around every run ([`settings::restoring`]).
//! - [`tune_ff`](mod@tune_ff): the feedforward gain from repeated sine tests.
//! - [`commission`](mod@commission): the motor's constants, the directions, the loops' gains; its estimators
//!   as pure functions of the recorded data in [`estimate`].
//!
//! Everything is also re-exported at the crate's root.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod client;
pub mod commission;
mod error;
pub mod estimate;
pub mod experiments;
pub mod frf;
pub mod identify;
pub mod ilc;
pub mod learn;
pub mod paramfile;
pub mod posmap;
pub mod settings;
pub mod tune_ff;

pub use client::*;
pub use commission::*;
pub use error::*;
pub use experiments::*;
pub use gms_link::{DeviceLink, Refusal};
pub use identify::*;
pub use tune_ff::*;
