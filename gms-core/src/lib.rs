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
//! use gms_core::{FrictionModel, Gms, presets};
//! let mut m = Gms::try_new(presets::table1()).unwrap();
//! // 50 urad at 1 mrad/s: pre-sliding, far below breakaway (220 uN·m).
//! let f = m.advance(50e-6, 0.05);
//! assert!(f > 0.0 && f < 220e-6);
//! ```
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod adaptive;
pub mod boards;
pub mod controller;
pub mod device;
pub mod drive;
pub mod error;
pub mod frf;
pub mod gms;
pub mod hw;
pub mod lugre;
pub mod math;
pub mod model;
pub mod numtext;
pub mod posmap;
pub mod presets;
pub mod protocol;
pub mod reference;
pub mod selftest;
#[cfg(feature = "serde")]
mod serde_array;
pub mod settings;
pub mod shaping;
pub mod static_map;
#[cfg(feature = "store")]
pub mod store;
pub mod stribeck;
pub mod table;

pub use error::{Field, ParamError, Side};
pub use gms::{Block, Gms, GmsParams, UNUSED_BLOCK};
pub use lugre::{LuGre, LugreParams};
pub use model::FrictionModel;
pub use static_map::{StaticMap, StaticParams};
pub use stribeck::{Stribeck, StribeckParams};
