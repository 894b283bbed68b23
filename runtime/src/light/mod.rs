//! What the light needs and which work a frame does: the light setup (shadow-map budget, ranges,
//! light grid, shadow faces: [`setup`]), the effect plan ([`plan`]) and which tiles' light may
//! still change ([`activity`]).

pub mod activity;
pub mod plan;
pub(crate) mod profile;
pub mod setup;
