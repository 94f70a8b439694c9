//! The position controller and what it runs on the device's loop: the references and moves
//! ([`mod@reference`]), the loop-shaping filters ([`shaping`]), the adaptive feedforward level
//! ([`adaptive`]), the position map ([`posmap`]), the learning's table motion ([`table`]),
//! the frequency-response lock-in ([`frf`]) and the chunk a long read is copied in
//! ([`chunk`]).

pub mod adaptive;
pub mod chunk;
pub mod controller;
pub mod frf;
pub mod posmap;
pub mod reference;
pub mod shaping;
pub mod table;
