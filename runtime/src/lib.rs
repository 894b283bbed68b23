//! The grotto runtime. Today: describing and verifying packages ([`inspect`]); the wgpu passes,
//! residency and effect plan of the design brief land here next.

pub mod inspect;
