//! The frame-time target the viewers hold while the camera moves (`grotto view` and the browser
//! viewer): after each moving frame the draw's time is compared with the target, and the next
//! moving frame trades what it must: first the render scale (pixels go with its square), then,
//! once the scale is at its floor, the level of detail (far surfel chunks thinned harder:
//! render/chunks.rs `Lod`, the detail factor multiplying its pixel floor). A frame well under the
//! target gives back detail first, then scale. At rest the viewers draw at full scale and detail
//! and spend the rest of the frame on light (window/pace.rs). Pure bookkeeping, tested here.

use serde::Serialize;

/// The default target: 60 frames a second.
pub const DEFAULT_TARGET_MS: f64 = 1000.0 / 60.0;

/// The smallest render scale the target may choose (of the viewer's own scale): a quarter of
/// the width, a sixteenth of the pixels.
pub const MIN_SCALE: f32 = 0.25;

/// The largest detail factor: a chunk is thinned until its discs reach this many times the
/// pixel floor (at 8, a 0.75-pixel floor becomes 6 pixels, the chunks' thinning capped at 1 in
/// 16 surfels).
pub const MAX_DETAIL: f32 = 8.0;

/// What the target traded for time, as the panel shows it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Traded {
    pub target_ms: f64,
    /// The last moving frame's draw, milliseconds.
    pub draw_ms: Option<f64>,
    /// Render scale while moving (1: the viewer's own).
    pub scale: f32,
    /// Pixel floor multiplier for the level of detail while moving (1: none traded).
    pub detail: f32,
}

/// A frame-time target and what it currently trades.
#[derive(Clone, Debug)]
pub struct FrameTarget {
    target_ms: f64,
    draw_ms: Option<f64>,
    scale: f32,
    detail: f32,
}

impl FrameTarget {
    /// A target of `target_ms` a frame (non-finite or non-positive: the default).
    pub fn new(target_ms: f64) -> Self {
        let target_ms = if target_ms.is_finite() && target_ms > 0.0 { target_ms } else { DEFAULT_TARGET_MS };
        Self { target_ms, draw_ms: None, scale: 1.0, detail: 1.0 }
    }

    /// What a frame draws with: the traded scale and detail while `moving`, none at rest.
    pub fn for_frame(&self, moving: bool) -> (f32, f32) {
        if moving { (self.scale, self.detail) } else { (1.0, 1.0) }
    }

    /// A moving frame's draw took `ms`: choose what the next one trades. Steps are bounded (a
    /// frame up to four times over the target, a tile swap or a hiccup of the OS, moves the scale
    /// by at most 30%; one further over takes the whole step, so a weak adapter is not frozen for
    /// several full-size frames), and a band of 20% under the target holds still so the image
    /// does not flicker between sizes.
    pub fn record_moving(&mut self, ms: f64) {
        if !ms.is_finite() || ms < 0.0 {
            return;
        }
        // The last frame alone: each step changes what a frame costs, so an average over
        // frames would answer for sizes no longer drawn (the bounded steps keep one odd frame
        // from moving much).
        self.draw_ms = Some(ms);
        let ratio = (self.target_ms / ms.max(1e-3)) as f32;
        if ratio < 1.0 {
            // Far over the target (four times and more: a weak adapter, or the first moving
            // frame after a full-size one), the whole step at once; else bounded steps.
            let far = ratio < 0.25;
            if self.scale > MIN_SCALE {
                // Pixels go with the square of the scale.
                let step = if far { ratio.sqrt() } else { ratio.sqrt().clamp(0.7, 1.0) };
                self.scale = (self.scale * step).max(MIN_SCALE);
            } else {
                let step = if far { 4.0 } else { 1.0 / ratio.clamp(0.5, 1.0) };
                self.detail = (self.detail * step).min(MAX_DETAIL);
            }
        } else if ratio > 1.25 {
            if self.detail > 1.0 {
                self.detail = (self.detail / ratio.clamp(1.0, 1.5)).max(1.0);
            } else {
                self.scale = (self.scale * ratio.sqrt().clamp(1.0, 1.2)).min(1.0);
            }
        }
    }

    /// What is traded now.
    pub fn traded(&self) -> Traded {
        Traded { target_ms: self.target_ms, draw_ms: self.draw_ms, scale: self.scale, detail: self.detail }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A draw whose time goes with the pixels drawn, and, past the scale floor, with detail.
    fn cost(full_ms: f64, t: &FrameTarget) -> f64 {
        let (scale, detail) = t.for_frame(true);
        full_ms * f64::from(scale * scale).max(0.0) / f64::from(detail)
    }

    #[test]
    fn a_slow_draw_trades_scale_then_detail_until_it_holds_the_target() {
        let mut t = FrameTarget::new(16.7);
        for _ in 0..40 {
            let ms = cost(100.0, &t);
            t.record_moving(ms);
        }
        let ms = cost(100.0, &t);
        assert!(ms <= 16.7 * 1.05, "held the target: {ms} ms ({:?})", t.traded());
        assert!(t.traded().scale > MIN_SCALE - 1e-6 && t.traded().scale < 1.0);
        assert_eq!(t.for_frame(false), (1.0, 1.0), "at rest nothing is traded");

        // An adapter this slow needs detail too: 400 ms at full scale is 25 ms at the floor.
        let mut slow = FrameTarget::new(16.7);
        for _ in 0..60 {
            let ms = cost(400.0, &slow);
            slow.record_moving(ms);
        }
        let tr = slow.traded();
        assert_eq!(tr.scale, MIN_SCALE);
        assert!(tr.detail > 1.0 && cost(400.0, &slow) <= 16.7 * 1.05, "{tr:?}");

        // A frame far over the target (SwiftShader: 7 s at full size) reaches the floors at once.
        let mut weak = FrameTarget::new(16.7);
        weak.record_moving(7000.0);
        assert_eq!(weak.traded().scale, MIN_SCALE);
        weak.record_moving(7000.0 * 0.0625);
        assert_eq!(weak.traded().detail, 4.0);
    }

    #[test]
    fn a_fast_draw_gives_back_detail_then_scale_and_bad_times_change_nothing() {
        let mut t = FrameTarget::new(16.7);
        for _ in 0..60 {
            let ms = cost(400.0, &t);
            t.record_moving(ms);
        }
        // The scene got cheap (tiles left the view): everything comes back.
        for _ in 0..60 {
            let ms = cost(2.0, &t);
            t.record_moving(ms);
        }
        assert_eq!((t.traded().scale, t.traded().detail), (1.0, 1.0));
        for bad in [f64::NAN, f64::INFINITY, -1.0] {
            t.record_moving(bad);
        }
        assert_eq!((t.traded().scale, t.traded().detail), (1.0, 1.0));
        assert_eq!(FrameTarget::new(f64::NAN).traded().target_ms, DEFAULT_TARGET_MS);
    }
}
