//! gms-core's integration tests in one binary: each file below is a module (one link
//! instead of one per file; `cargo test -p gms-core --test all -- MODULE::` runs one file's tests).

mod adaptive;
mod device;
mod drive;
mod frf;
mod gms_properties;
mod hw;
mod integral;
mod layers;
mod math_accuracy;
mod models;
mod motion;
mod numtext;
mod posmap;
mod protocol;
mod protocol_doc;
#[cfg(feature = "store")]
mod record;
mod replies;
mod reply;
mod shaping;
mod status;
#[cfg(feature = "store")]
mod store;
mod table;
