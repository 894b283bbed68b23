//! How streaming fares against the web: a failed step is tried again after 1, 2, 4 and 8 s where
//! asking again may help (a 5xx, a dropped connection, a deadline, a short body), and stops
//! otherwise (a 404, a server that lies about ranges, a package replaced mid-visit); a tile whose
//! finer sections arrived damaged is held at the form it had. The view keeps what it has and
//! the page says what happened: nothing here ends a visit.

use std::collections::BTreeMap;

use grotto_format::Package;
use grotto_runtime::scene::data::TileMode;
use grotto_runtime::stream::residency::Residency;
use web_time::{Duration, Instant};

use crate::error::Error;

/// Tries of a failing step before streaming stops.
const MAX_ATTEMPTS: u32 = 4;

#[derive(Debug, Default)]
pub(crate) struct Health {
    /// Failed tries of the step now due.
    attempts: u32,
    retry_at: Option<Instant>,
    stopped: bool,
    replaced: bool,
    /// Tiles held back, and the finest form each may take.
    pub damaged: BTreeMap<usize, TileMode>,
    notice: Option<String>,
    /// Failed steps over the visit (the status's `stream_failures`).
    failures: u32,
}

impl Health {
    /// A step arrived whole.
    pub(crate) fn succeeded(&mut self) {
        self.attempts = 0;
        self.retry_at = None;
        if self.damaged.is_empty() && !self.stopped {
            self.notice = None;
        }
    }

    /// A step's fetch failed with `e`: tried again later, or streaming stops; anything but a
    /// fetch problem is the caller's to report.
    pub(crate) fn failed(&mut self, e: Error, now: Instant) -> Result<(), Error> {
        self.failures += 1;
        match e {
            Error::Fetch { transient: true, .. } if self.attempts + 1 < MAX_ATTEMPTS => {
                let wait_s = 1u64 << self.attempts;
                self.attempts += 1;
                self.retry_at = Some(now + Duration::from_secs(wait_s));
                self.notice = Some(format!(
                    "{e}; trying again in {wait_s} s (try {} of {MAX_ATTEMPTS})",
                    self.attempts + 1
                ));
            }
            Error::Fetch { .. } => {
                self.stopped = true;
                self.notice = Some(format!("stopped fetching finer tiles: {e}; the view shows what arrived"));
            }
            Error::Replaced { .. } => {
                self.stopped = true;
                self.replaced = true;
                self.notice = Some(e.to_string());
            }
            other => return Err(other),
        }
        Ok(())
    }

    /// Whether a step may be fetched now.
    pub(crate) fn may_fetch(&self, now: Instant) -> bool {
        !self.stopped && self.retry_at.is_none_or(|t| now >= t)
    }

    pub(crate) fn stopped(&self) -> bool {
        self.stopped
    }

    /// "ok", "retrying", "stopped" or "replaced" (the status's `streaming`).
    pub(crate) fn state(&self) -> &'static str {
        match (self.replaced, self.stopped, self.retry_at.is_some()) {
            (true, _, _) => "replaced",
            (_, true, _) => "stopped",
            (_, _, true) => "retrying",
            _ => "ok",
        }
    }

    pub(crate) fn notice(&self) -> Option<String> {
        self.notice.clone()
    }

    pub(crate) fn failures(&self) -> u32 {
        self.failures
    }

    /// Loading the step `next` over `current` failed with a package error (`e`): finds the
    /// tiles at fault by loading each tile `next` changes on its own
    /// ([`grotto_runtime::stream::damaged_tiles`]), and holds each at its current form. Where no
    /// single tile fails (a damaged global section), streaming stops.
    pub(crate) fn damaged_step(&mut self, pkg: &Package, current: &Residency, next: &Residency, e: &Error) {
        let found = grotto_runtime::stream::damaged_tiles(pkg, current, next);
        for d in &found {
            self.damaged.insert(d.tile, d.was);
        }
        if found.is_empty() {
            self.stopped = true;
            self.notice = Some(format!("stopped fetching finer tiles: {e}; the view shows what arrived"));
        } else {
            self.notice = Some(format!(
                "{} damaged in the package, shown at the form it had: {}",
                if found.len() == 1 { "a tile is" } else { "tiles are" },
                found
                    .iter()
                    .map(|d| format!("tile {} ({})", d.tile, d.problem))
                    .collect::<Vec<_>>()
                    .join("; ")
            ));
        }
    }
}
