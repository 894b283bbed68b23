//! Ground truth for grotto: converged Monte Carlo light transport on the same surfel scene the
//! runtime sees (its surfels as discs, with the runtime's splat scale; the same point and spot
//! lights; albedo from the surfel colours; emission from the leaves the surfels lie in).
//!
//! Path tracing with next-event estimation toward point and spot lights (shadow rays), cosine-
//! sampled diffuse bounces and Russian roulette, on the CPU with rayon; ray queries through a
//! `bvh` crate hierarchy over the discs. Every estimate comes with its standard error, so a
//! comparison can tell the runtime's error from the reference's own noise.
//!
//! Closest hits use growing ray segments (4 leaf sizes, then x4 each time): `bvh` returns every
//! disc whose box meets the query, so a short segment keeps the candidate set small in caves,
//! where most rays end on a nearby wall.

/// The path tracer: surfels as discs in a BVH, next-event estimation, Russian roulette.
mod tracer;
/// What the reference refuses.
mod error;
/// The scenes written for Mitsuba 3, to check the reference against an independent renderer.
pub mod mitsuba;
/// The accuracy-vs-time sweep behind docs/accuracy.md.
pub mod accuracy;
/// The true-surface benchmark: the synthetic cave's exact surface as a mesh for Mitsuba 3.
pub mod truth;

pub use error::Error;
pub use tracer::{Disc, Estimate, PathSettings, SurfelScene, aces_srgb, cosine_sample};
