//! Story files (`--story FILE` of `grotto publish`, `render` and `view`): points of interest and
//! tours in a manifest's `[[poi]]` and `[[tour]]` syntax (grotto_format::story), added to a
//! package's own.

use std::path::Path;

use grotto_format::story::{self, StorySpec};
use grotto_format::{Poi, Tour};

use crate::error::{Error, Result};

/// The story a site, a render or a window shows: the package's points of interest and tours, with those of the TOML
/// file `extra` (grotto_format::story::StorySpec) added, one named as one of the package's
/// replacing it; checked whole against the package's cameras, so a tour may stop at the
/// package's points of interest and the file's alike.
pub fn story_of(scene: &grotto_format::Scene, extra: Option<&Path>) -> Result<(Vec<Poi>, Vec<Tour>)> {
    let Some(path) = extra else { return Ok((scene.pois.clone(), scene.tours.clone())) };
    let problem = |reason: String| Error::Story { path: path.display().to_string(), problem: reason };
    let text = std::fs::read_to_string(path).map_err(|e| problem(e.to_string()))?;
    let spec: StorySpec = toml::from_str(&text).map_err(|e| problem(e.to_string()))?;
    let (pois, tours) = spec.convert();
    let pois = story::merged(&scene.pois, &pois, |p| &p.name);
    let tours = story::merged(&scene.tours, &tours, |t| &t.name);
    story::check(&pois, &tours, &scene.camera_names()).map_err(problem)?;
    Ok((pois, tours))
}
