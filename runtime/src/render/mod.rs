//! The renderer: the state it owns ([`renderer`]), the tile pools it writes tiles into
//! ([`pool`]), and the blit that shows a frame on a surface ([`present`]).

pub mod pool;
pub mod present;
pub mod renderer;
