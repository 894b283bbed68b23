//! What the reference refuses.

/// What the reference refuses.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Mitsuba's spot light falls off differently (linearly in angle, not the runtime's
    /// smoothstep in cosine), so a comparison would measure that difference, not the reference.
    #[error("light {0:?} is a spot light; only point lights are written for Mitsuba")]
    SpotForMitsuba(String),
    /// Mitsuba's point emitter is even in every direction; an IES or cosine profile would be lost.
    #[error("light {0:?} has a photometric profile; only even point lights are written for Mitsuba")]
    ProfileForMitsuba(String),
}
