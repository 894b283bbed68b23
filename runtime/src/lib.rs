//! The grotto runtime. Today: describing and verifying packages ([`inspect`]) and exporting their
//! points ([`export`]); the wgpu passes, residency and effect plan of the design brief land here
//! next.

pub mod export;
pub mod inspect;
