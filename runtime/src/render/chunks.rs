//! Surfel chunks: each tile's surfels in runs of [`CHUNK_SURFELS`] with the box their centres
//! fill and their largest radius, so a shadow face or the camera draws only the runs its frustum
//! (and, for a light, its range) meets. A tile box is too coarse for that: the demo cave has three
//! tiles and fourteen lamps, and every cube face of a lamp met every tile, so each face drew all
//! 402k discs to keep about a sixth of them. A package stores a tile's surfels in Morton order, so
//! a run is a compact patch of wall; the boxes are taken from the surfels themselves, so a scene
//! in another order is still drawn whole, only culled less.

use std::collections::HashMap;
use std::ops::Range;
use std::sync::Arc;

use glam::{Mat4, Vec2, Vec3};

use crate::gpu::types::SurfelGpu;
use crate::passes::splat::SplatRun;
use crate::render::pool::TileKey;

/// Surfels a chunk holds (the last one of a tile may hold fewer). A draw call per visible run of
/// chunks (adjacent ones merge), so smaller chunks cull tighter and cost more draws:
/// `grotto bench --json` counts both (docs/benchmarks.md "Surfel chunks").
pub(crate) const CHUNK_SURFELS: u32 = 1024;

/// One chunk: surfels `first..first + len` of its tile (offsets into the tile's own surfels), the
/// box of their centres, and their largest and mean stored radius.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Chunk {
    pub(crate) first: u32,
    pub(crate) len: u32,
    pub(crate) lo_m: Vec3,
    pub(crate) hi_m: Vec3,
    pub(crate) radius_m: f32,
    pub(crate) mean_radius_m: f32,
}

impl Chunk {
    /// The box the chunk's discs fill at `splat_scale` (before the pixel floor grows them).
    pub(crate) fn disc_box(&self, splat_scale: f32) -> (Vec3, Vec3) {
        let r = Vec3::splat(self.radius_m * splat_scale.max(0.0));
        (self.lo_m - r, self.hi_m + r)
    }
}

/// The chunks of one tile's surfels. A surfel with a non-finite centre draws nothing, so it
/// widens no box; a chunk of only such surfels gets an empty box (lo > hi) that no view meets.
pub(crate) fn chunks_of(surfels: &[SurfelGpu]) -> Vec<Chunk> {
    surfels
        .chunks(CHUNK_SURFELS as usize)
        .enumerate()
        .map(|(i, run)| {
            let (mut lo, mut hi, mut radius) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN), 0.0f32);
            let (mut sum, mut n) = (0.0f64, 0u32);
            for s in run {
                let p = Vec3::from_slice(&s.position_radius[..3]);
                if p.is_finite() {
                    lo = lo.min(p);
                    hi = hi.max(p);
                    let r = s.position_radius[3];
                    if r.is_finite() {
                        radius = radius.max(r.abs());
                        sum += f64::from(r.abs());
                        n += 1;
                    }
                }
            }
            let mean_radius_m = if n > 0 { (sum / f64::from(n)) as f32 } else { 0.0 };
            let first = i as u32 * CHUNK_SURFELS;
            Chunk { first, len: run.len() as u32, lo_m: lo, hi_m: hi, radius_m: radius, mean_radius_m }
        })
        .collect()
}

/// What a view may see: its view-projection, how far past the viewport's edges a disc's centre
/// may lie and still show (in NDC units per axis: the pixel floor grows far discs beyond their
/// world radius), and, for a light's face, the light's position and range (nothing beyond it is
/// lit, so nothing there casts a shadow that shows).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Viewer<'a> {
    pub(crate) view_proj: &'a Mat4,
    pub(crate) grow_ndc: Vec2,
    pub(crate) light: Option<(Vec3, f32)>,
    /// Thin far chunks to every k-th surfel (`None`: every surfel).
    pub(crate) lod: Option<Lod>,
}

/// Level of detail by size on screen: a chunk whose discs cover under `floor_px` pixels of
/// radius (the pixel floor every disc is grown to) draws every k-th surfel, k the largest power
/// of two up to [`MAX_STRIDE`] with sqrt(k) times its mean disc still within the floor.
/// Past the floor, discs already overlap many times over (each grown to the floor while their
/// spacing shrinks with distance), so thinning them changes which disc wins a pixel, not
/// whether the surface is closed: the thinned ones are grown by sqrt(k), and where that
/// reaches the floor they are as large as before.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Lod {
    pub(crate) eye_m: Vec3,
    /// Pixels per unit of (radius / distance): half the viewport height times the projection's
    /// y scale.
    pub(crate) focal_px: f32,
    pub(crate) floor_px: f32,
}

/// The sparsest thinning a chunk gets: 1 in 16 surfels.
pub(crate) const MAX_STRIDE: u32 = 16;

impl Lod {
    /// The stride for a chunk whose discs (of radius up to `radius_m`) fill `lo..hi`.
    pub(crate) fn stride(&self, lo: Vec3, hi: Vec3, radius_m: f32) -> u32 {
        let d = self.eye_m.clamp(lo, hi).distance(self.eye_m);
        let px = radius_m * self.focal_px / d;
        if px.is_nan() || px <= 0.0 || px.is_infinite() || self.floor_px <= px {
            return 1;
        }
        let k = ((self.floor_px / px).powi(2).min(MAX_STRIDE as f32) as u32).max(1);
        1 << k.ilog2()
    }
}

impl Viewer<'_> {
    /// How far (NDC) past the edges of a `width` x `height` viewport a disc grown to
    /// `min_splat_px` pixels of radius may reach: its radius, half again for the quad's slant
    /// and one pixel of rasterisation.
    pub(crate) fn grow_for(width: u32, height: u32, min_splat_px: f32) -> Vec2 {
        let px = 1.5 * min_splat_px.max(0.0) + 1.0;
        Vec2::new(2.0 * px / width.max(1) as f32, 2.0 * px / height.max(1) as f32)
    }

    /// Whether the box `lo..hi` may show.
    pub(crate) fn sees(&self, lo: Vec3, hi: Vec3) -> bool {
        if lo.cmpgt(hi).any() {
            return false;
        }
        if let Some((eye, range)) = self.light
            && eye.clamp(lo, hi).distance_squared(eye) > range * range
        {
            return false;
        }
        crate::view::camera::sees_box_grown(self.view_proj, lo, hi, self.grow_ndc)
    }
}

/// Each resident tile form's chunks, kept while the form stays resident so a change of tiles
/// reads only the surfels of the forms that came.
#[derive(Debug, Default)]
pub(crate) struct ChunkCache {
    by_key: HashMap<TileKey, Arc<Vec<Chunk>>>,
}

impl ChunkCache {
    /// The chunks of the tile form `key`, whose surfels are `surfels`, from the cache when it has
    /// them.
    pub(crate) fn get_or_build(&mut self, key: TileKey, surfels: &[SurfelGpu]) -> Arc<Vec<Chunk>> {
        self.by_key.entry(key).or_insert_with(|| Arc::new(chunks_of(surfels))).clone()
    }

    /// Keeps `chunks` as those of the tile form `key` (built as its surfels were written).
    pub(crate) fn insert(&mut self, key: TileKey, chunks: Vec<Chunk>) {
        self.by_key.insert(key, Arc::new(chunks));
    }

    /// Forgets the forms not in `keep`.
    pub(crate) fn retain(&mut self, keep: &std::collections::HashSet<TileKey>) {
        self.by_key.retain(|k, _| keep.contains(k));
    }
}

/// The pool runs of the chunks `viewer` may see, for tiles whose surfels sit at `tile_surfels`
/// in the pool, merged where adjacent. Chunk offsets past a tile's range (a cache built from
/// other surfels) are cut to it.
pub(crate) fn runs_seen<'c>(
    tiles: impl IntoIterator<Item = (&'c Range<u32>, &'c [Chunk])>,
    viewer: &Viewer<'_>,
    splat_scale: f32,
) -> Vec<SplatRun> {
    let mut runs: Vec<SplatRun> = Vec::new();
    for (at, chunks) in tiles {
        for c in chunks {
            let (lo, hi) = c.disc_box(splat_scale);
            if !viewer.sees(lo, hi) {
                continue;
            }
            // The typical disc, not the largest: a few large discs where the scan thins out
            // would hold a whole chunk at full detail, and each thinned disc grows by sqrt(k)
            // from its own radius, so a large one stays as closed as before.
            let stride = viewer.lod.map_or(1, |l| l.stride(lo, hi, c.mean_radius_m * splat_scale));
            let start = at.start.saturating_add(c.first).min(at.end);
            let end = start.saturating_add(c.len).min(at.end);
            if start < end {
                runs.push(SplatRun { surfels: start..end, stride });
            }
        }
    }
    merge(runs)
}

/// `runs` in pool order, adjacent ones of one stride joined.
pub(crate) fn merge(mut runs: Vec<SplatRun>) -> Vec<SplatRun> {
    runs.retain(|r| !r.surfels.is_empty());
    runs.sort_by_key(|r| r.surfels.start);
    let mut out: Vec<SplatRun> = Vec::with_capacity(runs.len());
    for r in runs {
        match out.last_mut() {
            Some(last) if last.surfels.end == r.surfels.start && last.stride == r.stride => {
                last.surfels.end = r.surfels.end;
            }
            _ => out.push(r),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn surfel(p: [f32; 3], r: f32) -> SurfelGpu {
        SurfelGpu {
            position_radius: [p[0], p[1], p[2], r],
            normal_spread: [0.0, 0.0, 1.0, 0.0],
            color: [255; 4],
            scan: 0,
        }
    }

    #[test]
    fn chunks_cover_every_surfel_and_box_their_discs() {
        let n = CHUNK_SURFELS as usize * 2 + 7;
        let surfels: Vec<SurfelGpu> = (0..n).map(|i| surfel([i as f32, 0.0, -(i as f32)], 0.5)).collect();
        let chunks = chunks_of(&surfels);
        assert_eq!(chunks.len(), 3);
        assert_eq!(chunks.iter().map(|c| c.len as usize).sum::<usize>(), n);
        assert_eq!(chunks[2].first, 2 * CHUNK_SURFELS);
        let (lo, hi) = chunks[1].disc_box(2.0);
        assert_eq!(lo, Vec3::new(1024.0 - 1.0, -1.0, -2047.0 - 1.0));
        assert_eq!(hi, Vec3::new(2047.0 + 1.0, 1.0, -1024.0 + 1.0));
    }

    #[test]
    fn non_finite_surfels_widen_no_box_and_a_chunk_of_them_is_never_seen() {
        let mut surfels = vec![surfel([f32::NAN, 0.0, 0.0], 1.0); CHUNK_SURFELS as usize];
        surfels.push(surfel([1.0, 2.0, 3.0], f32::INFINITY));
        surfels.push(surfel([f32::INFINITY, 0.0, 0.0], 1.0));
        let chunks = chunks_of(&surfels);
        let m = Mat4::IDENTITY;
        let viewer = Viewer { view_proj: &m, grow_ndc: Vec2::ZERO, light: None, lod: None };
        let (lo, hi) = chunks[0].disc_box(1.0);
        assert!(!viewer.sees(lo, hi), "a chunk of NaN centres has no box");
        assert_eq!(
            (chunks[1].lo_m, chunks[1].hi_m, chunks[1].radius_m, chunks[1].mean_radius_m),
            (Vec3::new(1.0, 2.0, 3.0), Vec3::new(1.0, 2.0, 3.0), 0.0, 0.0)
        );
    }

    /// Runs are the seen chunks at the tile's place in the pool, merged across tiles, and a
    /// light's range cuts what lies wholly beyond it.
    #[test]
    fn runs_follow_the_seen_chunks_and_the_light_range() {
        let proj = Mat4::perspective_rh(std::f32::consts::FRAC_PI_2, 1.0, 0.1, 1000.0);
        let view_proj = proj * Mat4::look_at_rh(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y);
        // Tile A: a chunk ahead (z = -5), a chunk behind (z = +5), a chunk ahead far away (z = -50).
        let k = CHUNK_SURFELS as usize;
        let mut a = vec![surfel([0.0, 0.0, -5.0], 0.1); k];
        a.extend(vec![surfel([0.0, 0.0, 5.0], 0.1); k]);
        a.extend(vec![surfel([0.0, 0.0, -50.0], 0.1); 10]);
        let b = vec![surfel([0.0, 0.0, -6.0], 0.1); 5];
        let n_a = a.len() as u32;
        let tiles = [(100..100 + n_a, chunks_of(&a)), (100 + n_a..105 + n_a, chunks_of(&b))];
        let all = Viewer { view_proj: &view_proj, grow_ndc: Vec2::ZERO, light: None, lod: None };
        let k = k as u32;
        let runs = |v: &Viewer<'_>| -> Vec<Range<u32>> {
            runs_seen(tiles.iter().map(|(at, c)| (at, c.as_slice())), v, 1.0)
                .into_iter()
                .map(|r| r.surfels)
                .collect()
        };
        assert_eq!(runs(&all), vec![100..100 + k, 100 + 2 * k..105 + n_a]);
        let lamp = Viewer { light: Some((Vec3::ZERO, 10.0)), ..all };
        assert_eq!(runs(&lamp), vec![100..100 + k, 100 + n_a..105 + n_a]);
    }

    #[test]
    fn a_disc_grown_to_the_pixel_floor_keeps_its_chunk_past_the_edge() {
        let proj = Mat4::perspective_rh(std::f32::consts::FRAC_PI_2, 1.0, 0.1, 1000.0);
        let view_proj = proj * Mat4::look_at_rh(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y);
        // A tiny disc 100 m ahead, its centre half a pixel (of 512) right of the edge.
        let x = 100.0 * (1.0 + 1.0 / 512.0);
        let (lo, hi) = (Vec3::new(x, 0.0, -100.0), Vec3::new(x, 0.0, -100.0));
        let tight = Viewer { view_proj: &view_proj, grow_ndc: Vec2::ZERO, light: None, lod: None };
        assert!(!tight.sees(lo, hi));
        let grown = Viewer { grow_ndc: Viewer::grow_for(512, 512, 0.75), ..tight };
        assert!(grown.sees(lo, hi));
    }

    /// Near chunks draw every surfel; a chunk's stride grows with the square of its distance
    /// once its discs shrink under the pixel floor, in powers of two up to MAX_STRIDE; a run
    /// of stride k covers the surfels at multiples of k.
    #[test]
    fn far_chunks_thin_by_the_square_of_their_distance() {
        let lod = Lod { eye_m: Vec3::ZERO, focal_px: 500.0, floor_px: 0.75 };
        let at = |d: f32| lod.stride(Vec3::new(0.0, 0.0, -d), Vec3::new(0.1, 0.1, -d), 0.01);
        // 0.01 m at 500 px: 5 px at 1 m, the floor (0.75 px) at 6.67 m.
        assert_eq!(at(1.0), 1);
        assert_eq!(at(6.0), 1);
        assert_eq!(at(10.0), 2); // (0.75 / 0.5)^2 = 2.25
        assert_eq!(at(20.0), 8); // 9
        assert_eq!(at(1000.0), MAX_STRIDE);
        assert_eq!(lod.stride(Vec3::splat(-1.0), Vec3::splat(1.0), 0.01), 1, "the eye inside the box");
        let run = SplatRun { surfels: 5..21, stride: 4 };
        assert_eq!(run.drawn(), 4, "8, 12, 16, 20");
        assert_eq!(
            merge(vec![
                SplatRun { surfels: 21..30, stride: 4 },
                run.clone(),
                SplatRun { surfels: 0..5, stride: 1 }
            ]),
            vec![SplatRun { surfels: 0..5, stride: 1 }, SplatRun { surfels: 5..30, stride: 4 }]
        );
    }
}
