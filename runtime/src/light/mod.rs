//! What the light needs and which work a frame does: the light setup (shadow-map budget, ranges,
//! light grid, shadow faces: [`setup`]), the effect plan ([`plan`]), which tiles' light may
//! still change ([`activity`]), and what a light edit in place redoes ([`edit`]).

pub mod activity;
pub mod edit;
pub mod plan;
pub(crate) mod profile;
pub mod setup;
