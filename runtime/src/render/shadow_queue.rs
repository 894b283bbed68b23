//! Which shadow faces the next shadow pass draws. Without a budget, every face out of date at
//! once (a change of lights: all of them; a change of tiles: those that see one). Under a
//! per-frame budget (`Settings::shadow_frame_ms`, what a viewer sets), as many faces as the
//! milliseconds allow at the pass's measured surfels per millisecond, the rest over the next
//! frames: the worst single-frame stall is then one face, not the whole atlas.
//!
//! While faces are drawn over several frames the image stays consistent: they go into a staging
//! atlas (passes/shadow.rs) and are copied over the shown one together when the last is drawn,
//! so shading never mixes faces of two scenes, and direct light is injected once, from the whole
//! new atlas (the plan holds inject and the bounces until then: light/plan.rs). A staged face
//! that a later change leaves out of date waits for the next round, so rounds end (and inject)
//! while the tiles change every frame. The first fill
//! of a new renderer has nothing to keep: its faces go straight to the shown atlas, whose faces
//! not drawn yet read as all in shadow, so each light appears as its faces are drawn instead of
//! the image staying dark until the last. Bookkeeping only, tested here; the renderer computes
//! each face's surfel chunks when it marks the face.

use crate::passes::shadow::Batch;
use crate::passes::splat::SplatRun;

/// Surfels the first budgeted pass may draw before any pass was timed: a few milliseconds on
/// the slowest adapter measured (SwiftShader), a fraction of one on a discrete GPU, whose rate
/// the next frame then uses.
pub(crate) const START_SURFELS: u64 = 65_536;

/// Shadow faces out of date, those drawn to the staging atlas, and the measured rate.
#[derive(Clone, Debug)]
pub(crate) struct ShadowQueue {
    /// Per face, while out of date: the surfel chunks it draws and their surfels.
    dirty: Vec<Option<(Vec<SplatRun>, u64)>>,
    /// Faces drawn into the staging atlas and not shown yet.
    staged: Vec<bool>,
    /// Staged faces out of date again (tiles changed under them while the others caught up):
    /// drawn in the next round, so a change every frame cannot keep a round from ending.
    deferred: Vec<bool>,
    /// Surfels a millisecond the budgeted passes drew (a running mean), once one was timed.
    rate_per_ms: Option<f64>,
    /// Surfels of the last pass, until its time is known.
    untimed_surfels: u64,
    /// Every face has been drawn once: the shown atlas holds a whole set worth keeping.
    filled: bool,
}

impl ShadowQueue {
    /// `faces` faces, none out of date.
    pub(crate) fn new(faces: usize) -> Self {
        Self {
            dirty: vec![None; faces],
            staged: vec![false; faces],
            deferred: vec![false; faces],
            rate_per_ms: None,
            untimed_surfels: 0,
            filled: false,
        }
    }

    /// Face `face` is out of date and draws `runs` (replacing what it drew before: the pools may
    /// have moved since). A face already staged in the round under way waits for the next.
    pub(crate) fn mark(&mut self, face: usize, runs: Vec<SplatRun>) {
        if let Some(slot) = self.dirty.get_mut(face) {
            let surfels = runs.iter().map(SplatRun::drawn).sum();
            *slot = Some((runs, surfels));
            self.deferred[face] = self.staged[face];
        }
    }

    /// The atlas now has `faces` faces (a light edit in place added or removed some): new ones
    /// start up to date (the edit marks those it drew), dropped ones are forgotten.
    pub(crate) fn resize(&mut self, faces: usize) {
        self.dirty.resize(faces, None);
        self.staged.resize(faces, false);
        self.deferred.resize(faces, false);
    }

    /// Whether `face` is out of date.
    pub(crate) fn is_dirty(&self, face: usize) -> bool {
        self.dirty.get(face).is_some_and(Option::is_some)
    }

    /// Faces out of date.
    pub(crate) fn dirty_count(&self) -> usize {
        self.dirty.iter().filter(|d| d.is_some()).count()
    }

    /// The chunks face `face` draws while it is out of date.
    pub(crate) fn runs(&self, face: usize) -> &[SplatRun] {
        self.dirty.get(face).and_then(Option::as_ref).map_or(&[], |(r, _)| r.as_slice())
    }

    /// Surfels the next budgeted pass may draw within `frame_ms`.
    pub(crate) fn allowance(&self, frame_ms: f32) -> u64 {
        match self.rate_per_ms {
            Some(rate) => (rate * f64::from(frame_ms)).max(1.0) as u64,
            None => START_SURFELS,
        }
    }

    /// The faces the next pass draws within `frame_ms` (0 or less: all out of date). Faces go
    /// first-fit in atlas order: each one that fits what is left of the allowance is taken, and
    /// the first face out of date is taken whatever its size, so the queue always moves on. The
    /// pass finishes the round when it draws every face out of date but those deferred to the
    /// next round.
    pub(crate) fn batch(&self, frame_ms: f32) -> Batch {
        let budget = (frame_ms > 0.0).then(|| self.allowance(frame_ms));
        let mut b = Batch::default();
        let due: Vec<(usize, u64)> = (self.dirty.iter().enumerate())
            .filter(|(i, _)| !self.deferred[*i])
            .filter_map(|(i, d)| d.as_ref().map(|(_, n)| (i, *n)))
            .collect();
        for &(i, surfels) in &due {
            let fits = budget.is_none_or(|cap| b.faces.is_empty() || b.surfels + surfels <= cap);
            if fits {
                b.faces.push(i);
                b.surfels += surfels;
            }
        }
        b.finishes = b.faces.len() == due.len();
        let waiting = self.staged.iter().any(|&s| s);
        b.staged = self.filled && (!b.finishes || waiting);
        if b.staged && b.finishes {
            b.commit = (0..self.staged.len()).filter(|&i| self.staged[i] || b.faces.contains(&i)).collect();
        }
        b.whole = !b.staged && b.faces.len() == self.dirty.len();
        b
    }

    /// `batch` was drawn: its faces are up to date (staged, or shown when it finished).
    pub(crate) fn drawn(&mut self, batch: &Batch) {
        for &i in &batch.faces {
            self.dirty[i] = None;
            self.staged[i] = batch.staged && !batch.finishes;
        }
        if batch.finishes {
            self.staged.fill(false);
            // The faces deferred are out of date still, and start the next round.
            self.deferred.fill(false);
            self.filled = true;
        }
        self.untimed_surfels = batch.surfels;
    }

    /// The last pass took `ms` (its own time where the adapter gives it, or the frame's, which
    /// only overstates it): the rate the next budgets use.
    pub(crate) fn timed(&mut self, ms: f64) {
        let surfels = std::mem::take(&mut self.untimed_surfels);
        if surfels == 0 || !ms.is_finite() || ms <= 0.0 {
            return;
        }
        let rate = surfels as f64 / ms;
        // A mean over passes: one slow frame (the OS, a tile swap) moves the budget by half.
        self.rate_per_ms = Some(self.rate_per_ms.map_or(rate, |r| 0.5 * (r + rate)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn runs(n: u32) -> Vec<SplatRun> {
        vec![SplatRun::all(0..n)]
    }

    #[test]
    fn without_a_budget_every_face_out_of_date_is_drawn_at_once() {
        let mut q = ShadowQueue::new(4);
        for i in 0..4 {
            q.mark(i, runs(1000));
        }
        let b = q.batch(0.0);
        assert_eq!((b.faces.clone(), b.finishes, b.staged, b.whole), (vec![0, 1, 2, 3], true, false, true));
        q.drawn(&b);
        assert_eq!(q.dirty_count(), 0);
        // A change of tiles seen by two faces: those two, into the shown atlas, not cleared whole.
        q.mark(1, runs(10));
        q.mark(3, runs(10));
        let b = q.batch(0.0);
        assert_eq!((b.faces, b.staged, b.whole), (vec![1, 3], false, false));
    }

    /// A queue of `faces` faces whose first fill has been drawn.
    fn filled(faces: usize) -> ShadowQueue {
        let mut q = ShadowQueue::new(faces);
        q.drawn(&q.batch(0.0));
        q
    }

    #[test]
    fn the_first_fill_goes_straight_to_the_shown_atlas() {
        let mut q = ShadowQueue::new(3);
        for i in 0..3 {
            q.mark(i, runs(60_000));
        }
        let b = q.batch(8.0);
        assert_eq!((b.faces.clone(), b.staged, b.whole), (vec![0], false, false));
        q.drawn(&b);
        q.drawn(&q.batch(8.0));
        let b = q.batch(8.0);
        assert_eq!((b.faces.clone(), b.finishes, b.staged), (vec![2], true, false));
        q.drawn(&b);
        // Filled: a later change is staged.
        q.mark(0, runs(60_000));
        q.mark(1, runs(60_000));
        let b = q.batch(8.0);
        assert!(b.staged && !b.finishes, "{b:?}");
    }

    #[test]
    fn a_budget_spreads_the_faces_over_frames_staged_until_the_last() {
        let mut q = filled(6);
        for i in 0..6 {
            q.mark(i, runs(40_000));
        }
        // Untimed: the start allowance, one face (the first is taken whatever its size).
        let b = q.batch(8.0);
        assert_eq!((b.faces.clone(), b.finishes, b.staged), (vec![0], false, true));
        q.drawn(&b);
        // 40,000 surfels in 4 ms: 10,000 a ms; 8 ms then allows two faces.
        q.timed(4.0);
        assert_eq!(q.allowance(8.0), 80_000);
        let b = q.batch(8.0);
        assert_eq!(b.faces, vec![1, 2]);
        q.drawn(&b);
        q.timed(8.0);
        let mut frames = 2;
        loop {
            let b = q.batch(8.0);
            assert!(b.surfels <= q.allowance(8.0), "{b:?}");
            frames += 1;
            q.drawn(&b);
            q.timed(8.0);
            if b.finishes {
                assert!(b.staged);
                assert_eq!(b.commit, vec![0, 1, 2, 3, 4, 5], "every staged face shown together");
                break;
            }
            assert!(b.commit.is_empty(), "nothing shown before the last face: {b:?}");
        }
        assert_eq!(frames, 4);
        assert_eq!(q.dirty_count(), 0);
        // The next change starts with the rate measured.
        q.mark(5, runs(100));
        let b = q.batch(8.0);
        assert_eq!((b.faces, b.staged, b.finishes, b.commit.is_empty()), (vec![5], false, true, true));
    }

    #[test]
    fn a_face_marked_again_while_staged_waits_for_the_next_round_and_small_faces_fill_the_gaps() {
        let mut q = filled(3);
        q.mark(0, runs(50_000));
        q.mark(1, runs(50_000));
        q.mark(2, runs(10_000));
        q.timed(1.0); // nothing untimed: ignored
        let b = q.batch(8.0);
        // 65,536 allowed: face 0, face 1 does not fit, face 2 does.
        assert_eq!(b.faces, vec![0, 2]);
        q.drawn(&b);
        // Tiles changed again under face 0, staged but not shown: this round ends without it
        // (showing what it staged), and the next round draws it.
        q.mark(0, runs(50_000));
        let b = q.batch(8.0);
        assert_eq!((b.faces.clone(), b.finishes, b.commit.clone()), (vec![1], true, vec![0, 1, 2]));
        q.drawn(&b);
        assert_eq!(q.dirty_count(), 1);
        let b = q.batch(8.0);
        assert_eq!((b.faces.clone(), b.finishes, b.staged), (vec![0], true, false));
        q.drawn(&b);
        // Bad times change nothing.
        for bad in [f64::NAN, 0.0, -3.0] {
            q.drawn(&b);
            q.timed(bad);
        }
        assert_eq!(q.allowance(8.0), START_SURFELS);
    }

    #[test]
    fn a_change_every_frame_cannot_keep_a_round_from_ending() {
        let mut q = filled(4);
        for i in 0..4 {
            q.mark(i, runs(60_000));
        }
        // One face a pass; after each pass the tiles change under every face again.
        let mut rounds_ended = 0;
        for _ in 0..12 {
            let b = q.batch(8.0);
            assert!(!b.faces.is_empty(), "{b:?}");
            q.drawn(&b);
            if b.finishes {
                rounds_ended += 1;
                assert!(!b.commit.is_empty());
            }
            for i in 0..4 {
                q.mark(i, runs(60_000));
            }
        }
        assert!(rounds_ended >= 2, "rounds ended: {rounds_ended}");
        assert_eq!(q.dirty_count(), 4, "and the faces stay out of date while the tiles change");
    }
}
