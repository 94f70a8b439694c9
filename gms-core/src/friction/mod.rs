//! The friction models: the Generalized Maxwell-Slip model of the paper ([`gms`]), LuGre and
//! a static map for comparison, behind one trait ([`model::FrictionModel`]), with the
//! Stribeck curve they share, the paper's parameter sets and the parameter errors.

pub mod error;
pub mod gms;
pub mod lugre;
pub mod model;
pub mod presets;
#[cfg(feature = "serde")]
mod serde_array;
pub mod static_map;
pub mod stribeck;
