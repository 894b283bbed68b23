//! The page's points of interest and tours: viewer.json's (what `grotto publish` writes: the
//! package's amended by `--story`), else the package's own; the guide that labels, flies, plays
//! and measures is the runtime's (grotto_runtime::guide, the window's too).

use grotto_format::{Poi, Tour};
use grotto_runtime::engine::Story;
use serde::Deserialize;

use crate::error::Error;

/// viewer.json's points of interest and tours (what `grotto publish` writes: the package's
/// amended by `--story`), checked against the package's cameras; None where it gives none (the
/// package's own are shown).
pub(crate) fn given(
    scene: &grotto_format::Scene,
    given: Option<&serde_json::Value>,
) -> Result<Option<Story>, Error> {
    #[derive(Deserialize)]
    struct Given {
        #[serde(default)]
        pois: Vec<Poi>,
        #[serde(default)]
        tours: Vec<Tour>,
    }
    let Some(v) = given else { return Ok(None) };
    let g: Given =
        serde_json::from_value(v.clone()).map_err(|e| Error::Setting(format!("viewer.json story: {e}")))?;
    grotto_format::story::check(&g.pois, &g.tours, &scene.camera_names())
        .map_err(|e| Error::Setting(format!("viewer.json story: {e}")))?;
    Ok(Some(Story { pois: g.pois, tours: g.tours, cameras: scene.cameras.clone() }))
}
