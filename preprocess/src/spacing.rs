//! The point spacing of a set of scans, measured on a sample of each (what `--leaf-m auto`
//! chooses the leaf size from).

use rayon::prelude::*;

use crate::Result;
use crate::ingest::{self, PointChunk};
use crate::manifest::ResolvedScan;

/// The median distance from a point to its nearest distinct neighbour, in metres, over the first
/// `per_scan` points of each scan (posed into the world), with the number of points it was taken
/// over; None with fewer than two distinct points. Consecutive points of a scan lie together (a
/// scan line, a flight strip), so a scan's first points measure its spacing where a random sample
/// of a large survey would be too sparse to.
pub(crate) fn sample_spacing_m(scans: &[ResolvedScan], per_scan: usize) -> Result<Option<(f64, usize)>> {
    // Scans in parallel (each decoder is one thread's work), in order for the same median.
    let per_scan_spacings: Vec<(Vec<f64>, usize)> = scans
        .par_iter()
        .map(|scan| -> Result<(Vec<f64>, usize)> {
            // The LAZ reader decodes LAZ_BATCH requests' worth at once: requests of a full chunk
            // made a 10^5-point sample decode 5 * 10^5 points of each LAZ scan (half the time of
            // `--leaf-m auto` at 10^8).
            let mut chunk =
                PointChunk::new(per_scan.div_ceil(ingest::LAZ_BATCH).clamp(1, ingest::DEFAULT_CHUNK));
            let mut source = ingest::open_positions(&scan.path, scan.format, scan.index)?;
            let mut pts: Vec<[f64; 3]> = Vec::new();
            while pts.len() < per_scan && source.fill_chunk(&mut chunk)? > 0 {
                pts.extend(
                    chunk
                        .xyz
                        .iter()
                        .map(|p| scan.world_from_scan.apply(*p))
                        .filter(|p| p.iter().all(|c| c.is_finite()))
                        .take(per_scan - pts.len()),
                );
            }
            let Some(first) = pts.first().copied() else { return Ok((Vec::new(), 0)) };
            // Centred before the cast: survey coordinates in f32 would round to decimetres.
            let local: Vec<[f32; 3]> =
                pts.iter().map(|p| [0, 1, 2].map(|a| (p[a] - first[a]) as f32)).collect();
            let (_, knn) = crate::knn::Knn::new(&local);
            // The nearest neighbour at a non-zero distance (duplicates say nothing of spacing)
            // is the smallest of the 8 nearest; queries in Morton order reuse the kNN's cells.
            let mut cache = crate::knn::CellCache::default();
            let mut nbs = Vec::with_capacity(8);
            let mut spacing = Vec::with_capacity(local.len());
            // The previous query's 8th distance, widened, as the guess of this one's (exact
            // whatever the guess; a good one skips most candidates, as in normals.rs).
            let mut guess_d2 = f32::INFINITY;
            for j in 0..local.len() {
                knn.nearest(j, 8, guess_d2, &mut cache, &mut nbs);
                let d2 = nbs.iter().map(|nb| nb.0).fold(0.0f32, f32::max);
                guess_d2 = if d2 > 0.0 { d2 * crate::normals::KNN_BOUND_FACTOR } else { f32::INFINITY };
                if let Some(d2) = nbs.iter().map(|nb| nb.0).filter(|&d2| d2 > 0.0).reduce(f32::min) {
                    spacing.push(f64::from(d2).sqrt());
                }
            }
            Ok((spacing, pts.len()))
        })
        .collect::<Result<_>>()?;
    let sampled: usize = per_scan_spacings.iter().map(|s| s.1).sum();
    let mut spacings: Vec<f64> = per_scan_spacings.into_iter().flat_map(|s| s.0).collect();
    if spacings.is_empty() {
        return Ok(None);
    }
    let mid = spacings.len() / 2;
    let median = *spacings.select_nth_unstable_by(mid, f64::total_cmp).1;
    Ok(Some((median, sampled)))
}
