//! The suites: each measures one part of grotto with the project's own commands, writes its
//! tables and raw reports to `OUT/SUITE/`, and returns the rows it owns on the figures page.

mod frames;
mod gpu;
mod maps;
mod memory;
mod package;
mod web;
mod window;

use anyhow::Result;

use crate::figures::Figure;
use crate::runner::Ctx;

/// What a suite needs beyond the built binaries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Needs {
    /// The binaries and a wgpu adapter (a GPU or Mesa's software drivers).
    Binaries,
    /// An X server (Xvfb) and xdotool.
    Display,
    /// Chromium, chromedriver and the wasm target (the browser tests' tools).
    Browser,
}

#[derive(Debug)]
pub(crate) struct Suite {
    pub(crate) name: &'static str,
    pub(crate) about: &'static str,
    pub(crate) needs: Needs,
    /// Rough time on the project's 2-core machine.
    pub(crate) dev_time: &'static str,
    pub(crate) run: fn(&Ctx) -> Result<Vec<Figure>>,
}

pub(crate) const SUITES: &[Suite] = &[
    Suite {
        name: "demo",
        about: "scripts/demo.sh from start to end",
        needs: Needs::Binaries,
        dev_time: "8 min",
        run: package::demo,
    },
    Suite {
        name: "format",
        about: "Package::open on 10 MB and 2 GB (criterion)",
        needs: Needs::Binaries,
        dev_time: "2 min",
        run: package::format,
    },
    Suite {
        name: "ingest",
        about: "points a second of each reader, 10^7 points",
        needs: Needs::Binaries,
        dev_time: "5 min",
        run: package::ingest,
    },
    Suite {
        name: "normals",
        about: "normal accuracy and speed, with and without scanner positions",
        needs: Needs::Binaries,
        dev_time: "5 min",
        run: package::normals,
    },
    Suite {
        name: "build",
        about: "a 10^8-point build end to end; package bytes per point",
        needs: Needs::Binaries,
        dev_time: "25 min, 15 GB",
        run: package::build,
    },
    Suite {
        name: "passes",
        about: "per-pass times of the cave paper's configurations",
        needs: Needs::Binaries,
        dev_time: "10 min",
        run: frames::passes,
    },
    Suite {
        name: "lights",
        about: "cost against the number of lights, 1 to 1024 lamps",
        needs: Needs::Binaries,
        dev_time: "15 min",
        run: frames::lights,
    },
    Suite {
        name: "first-frame",
        about: "first frame of 10^8 points under 64 MiB",
        needs: Needs::Binaries,
        dev_time: "20 min, 15 GB",
        run: frames::first_frame,
    },
    Suite {
        name: "flythrough",
        about: "a fly-through under 64 MiB, frame by frame (a table)",
        needs: Needs::Binaries,
        dev_time: "5 min",
        run: frames::flythrough,
    },
    Suite {
        name: "memory",
        about: "grotto render's and view's process peak, 10^7 points under 256 MiB",
        needs: Needs::Display,
        dev_time: "10 min",
        run: memory::render,
    },
    Suite {
        name: "memory-1e8",
        about: "as memory, of 10^8 points (builds the 10^8 package once)",
        needs: Needs::Display,
        dev_time: "30 min",
        run: memory::render_1e8,
    },
    Suite {
        name: "map",
        about: "grotto map of the 10^7- and 10^8-point surveys (needs cavern)",
        needs: Needs::Binaries,
        dev_time: "30 min, 15 GB",
        run: maps::survey,
    },
    Suite {
        name: "gpu-demo",
        about: "the demo cave per preset, its splat work, blended splats",
        needs: Needs::Binaries,
        dev_time: "GPU: 1 min",
        run: gpu::demo,
    },
    Suite {
        name: "gpu-paper",
        about: "the cave paper's configurations at 800x600 and 1600x900",
        needs: Needs::Binaries,
        dev_time: "GPU: 1 min",
        run: gpu::paper,
    },
    Suite {
        name: "gpu-1e7",
        about: "a 10^7-point survey, every tile held, 1920x1080",
        needs: Needs::Binaries,
        dev_time: "GPU: 2 min",
        run: gpu::survey_1e7,
    },
    Suite {
        name: "gpu-1e8",
        about: "a 10^8-point survey streamed under 512 MiB, 1920x1080",
        needs: Needs::Binaries,
        dev_time: "GPU: 4 min",
        run: gpu::survey_1e8,
    },
    Suite {
        name: "view",
        about: "the window's frames moving and at rest (Xvfb)",
        needs: Needs::Display,
        dev_time: "4 min",
        run: window::view,
    },
    Suite {
        name: "soak",
        about: "the window's memory over 30 minutes of flight (Xvfb)",
        needs: Needs::Display,
        dev_time: "32 min",
        run: window::soak,
    },
    Suite {
        name: "soak-phone",
        about: "the window's memory over 30 minutes of flight, 10^7 points under --memory phone (Xvfb)",
        needs: Needs::Display,
        dev_time: "32 min",
        run: window::soak_phone,
    },
    Suite {
        name: "web",
        about: "bytes before the page's first frame; the bundle's size",
        needs: Needs::Browser,
        dev_time: "6 min",
        run: web::bytes,
    },
    Suite {
        name: "web-frames",
        about: "the page's frames while moving",
        needs: Needs::Browser,
        dev_time: "6 min",
        run: web::frames,
    },
    Suite {
        name: "web-memory",
        about: "the page's memory over 30 minutes of its tour",
        needs: Needs::Browser,
        dev_time: "35 min",
        run: web::memory,
    },
];

/// Names that stand for several suites.
pub(crate) const GROUPS: &[(&str, &[&str])] = &[("gpu", &["gpu-demo", "gpu-paper", "gpu-1e7", "gpu-1e8"])];

pub(crate) fn find(name: &str) -> Option<&'static Suite> {
    SUITES.iter().find(|s| s.name == name)
}

/// The suites `names` stand for, in order, groups expanded; the unknown name if any.
pub(crate) fn resolve(names: &[String]) -> Result<Vec<&'static Suite>, String> {
    let mut out = Vec::new();
    for n in names {
        match GROUPS.iter().find(|(g, _)| g == n) {
            Some((_, members)) => out.extend(members.iter().filter_map(|m| find(m))),
            None => out.push(find(n).ok_or_else(|| n.clone())?),
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_group_names_suites_and_every_suite_is_named_once() {
        for (g, members) in GROUPS {
            assert!(find(g).is_none(), "group {g} shadows a suite");
            for m in *members {
                assert!(find(m).is_some(), "group {g}: no suite {m}");
            }
        }
        let mut names: Vec<_> = SUITES.iter().map(|s| s.name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), SUITES.len());
        assert_eq!(resolve(&["gpu".into(), "view".into()]).unwrap().len(), 5);
        assert_eq!(resolve(&["nope".into()]).unwrap_err(), "nope");
    }

    #[test]
    fn every_row_of_the_figures_page_that_names_a_suite_names_one_here() {
        let figures = crate::figures::Figures::load(&crate::figures::json_path()).unwrap();
        for f in &figures.figures {
            if let Some(s) = &f.suite {
                assert!(find(s).is_some(), "{}: no suite {s:?}", f.id);
            }
        }
    }
}
