//! # gms-core
//!
//! Friction models for ultra-high-precision positioning, `no_std`, without allocation or
//! `unsafe`, f32 throughout: the Generalized Maxwell-Slip model [`Gms`] of Zelenika & Kamenar
//! (paper eqs 1-6), and for comparison [`LuGre`] and a [`StaticMap`], all behind
//! [`FrictionModel`]. Parameters are plain structs validated once into the model
//! ([`Gms::try_new`]); an invalid set cannot be constructed and the [`ParamError`] names the
//! field.
//!
//! Units are SI and consistent within a model: N and m for a translational axis, N·m and rad
//! for a rotational one, s for time.
//!
//! ```
//! use gms_core::{FrictionModel, Gms};
//! use gms_core::friction::presets;
//! let mut m = Gms::try_new(presets::table1()).unwrap();
//! // 50 urad at 1 mrad/s: pre-sliding, far below breakaway (220 uN·m).
//! let f = m.advance(50e-6, 0.05);
//! assert!(f > 0.0 && f < 220e-6);
//! ```
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

// The layers, from the bottom: each module uses only those above it in this list (checked by
// `tests/layers.rs`).
//
// - base: `math`, `numtext`, `crc`, `settings` (the parameters' one table);
// - `friction`: the friction models;
// - `control`: the controller and what it runs (references, shaping, the position map, the
//   table motion, the frequency-response lock-in, the chunk a read is copied in);
// - `drive`: the motor driver's pure logic (encoder, sense, faults, bridge, deadman, stats);
// - `protocol`: the bench protocol (requests, replies, the parameter table's access);
// - `device`: the device core (the control loop and the protocol side, the stored record);
// - `boards`: the boards the firmware runs on (clock trees, memory maps, power stages);
// - `selftest`: a fixed workload over everything, for the host/target equivalence.
pub mod boards;
pub mod control;
pub mod crc;
pub mod device;
pub mod drive;
pub mod friction;
pub mod math;
pub mod numtext;
pub mod protocol;
pub mod selftest;
pub mod settings;

pub use friction::error::{Field, ParamError, Side};
pub use friction::gms::{Block, Gms, GmsParams, UNUSED_BLOCK};
pub use friction::lugre::{LuGre, LugreParams};
pub use friction::model::FrictionModel;
pub use friction::static_map::{StaticMap, StaticParams};
pub use friction::stribeck::{Stribeck, StribeckParams};
