//! The page's points of interest and tours: viewer.json's (what `grotto publish` writes: the
//! package's amended by `--story`), else the package's own; the guide that labels, flies, plays
//! and measures is the runtime's (grotto_runtime::guide, the window's too).

use grotto_runtime::guide::Guide;
use grotto_runtime::scene::data::SceneData;
use serde::Deserialize;

use crate::error::Error;

/// The points of interest and tours the page shows: `given` (viewer.json's, which `grotto
/// publish` writes: the package's amended by `--story`), checked against the package's cameras,
/// else the package's own.
pub(crate) fn story_for(
    far: &SceneData,
    scene: &grotto_format::Scene,
    given: Option<&serde_json::Value>,
) -> Result<Guide, Error> {
    #[derive(Deserialize)]
    struct Given {
        #[serde(default)]
        pois: Vec<grotto_format::Poi>,
        #[serde(default)]
        tours: Vec<grotto_format::Tour>,
    }
    let (pois, tours) = match given {
        Some(v) => {
            let g: Given = serde_json::from_value(v.clone())
                .map_err(|e| Error::Setting(format!("viewer.json story: {e}")))?;
            grotto_format::story::check(&g.pois, &g.tours, &scene.camera_names())
                .map_err(|e| Error::Setting(format!("viewer.json story: {e}")))?;
            grotto_runtime::scene::story::in_frame(far.frame_origin_m, &g.pois, &g.tours, &scene.cameras)
        }
        None => (far.pois.clone(), far.tours.clone()),
    };
    Ok(Guide::new(pois, tours, far.frame_origin_m))
}
