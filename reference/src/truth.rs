//! The true-surface benchmark: how close grotto's picture of the scanned points is to
//! the cave itself. The synthetic cave (`grotto-pack synth`, preprocess/src/synth.rs) is an
//! implicit function, so its true surface is known. This meshes it (Naive Surface Nets, the
//! `fast-surface-nets` crate, on a grid far finer than a leaf) with the cave's own colours as
//! linear vertex albedo, and writes a Mitsuba 3 scene of that mesh per camera with the package's
//! lights and camera: `direct` (direct light alone, Mitsuba's `direct` integrator) and `path`
//! (full transport, unbounded depth). `scripts/truth-check.py` renders them and judges grotto's
//! renders of the package against them (FLIP and relative RMSE over every pixel, silhouettes and
//! holes included): docs/accuracy-truth.md.
//!
//! The scene writing is by hand for the reason `mitsuba.rs` gives: Mitsuba's XML and PLY layout
//! are its own formats, and this mapping is the project's.

use std::collections::HashSet;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

use fast_surface_nets::ndshape::{ConstShape, ConstShape3u32};
use fast_surface_nets::{SurfaceNetsBuffer, surface_nets};
use glam::DVec3;
use grotto_preprocess::synth::{GRID_CELL_M, SynthCave};
use grotto_runtime::scene::data::SceneLight;
use grotto_runtime::view::camera::Camera;
use rayon::prelude::*;

/// Cells per meshing chunk side; a chunk holds its cells plus one sample of padding each side,
/// so neighbouring chunks' meshes meet without seams (the crate's convention).
const CHUNK_CELLS: u32 = 32;
type ChunkShape = ConstShape3u32<{ CHUNK_CELLS + 2 }, { CHUNK_CELLS + 2 }, { CHUNK_CELLS + 2 }>;

/// The cave's true surface as triangles, in the package's frame (metres).
#[derive(Debug, Default)]
pub struct TruthMesh {
    pub positions: Vec<[f32; 3]>,
    /// Unit normals into the open cave.
    pub normals: Vec<[f32; 3]>,
    /// Linear albedo (the cave's sRGB colour decoded).
    pub albedo: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
}

/// Meshes `cave`'s wall at `cell_m` (a cube grid in the cave's local frame), moved into the
/// package's frame by `frame_from_local_m` (the survey offset minus the package's origin).
/// `progress(done, total)` after each chunk.
pub fn mesh_cave(
    cave: &SynthCave,
    cell_m: f64,
    frame_from_local_m: DVec3,
    progress: impl Fn(usize, usize) + Sync,
) -> TruthMesh {
    let chunk_m = f64::from(CHUNK_CELLS) * cell_m;
    // Every chunk of the global chunk lattice that overlaps a grid cube where a wall may lie.
    let mut chunks = HashSet::new();
    for lo in cave.occupied_cells() {
        let a = lo.map(|v| (v / chunk_m).floor() as i64);
        let b = lo.map(|v| ((v + GRID_CELL_M) / chunk_m).ceil() as i64);
        for x in a[0]..b[0] {
            for y in a[1]..b[1] {
                for z in a[2]..b[2] {
                    chunks.insert([x, y, z]);
                }
            }
        }
    }
    let mut chunks: Vec<[i64; 3]> = chunks.into_iter().collect();
    chunks.sort_unstable();
    let total = chunks.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    // The wall function is close to a distance (its noise makes it up to ~1.4x steeper): a chunk
    // whose centre is further from the wall than twice its half-diagonal holds none of it.
    let skip_beyond_m = 2.0 * 0.5 * chunk_m * 3f64.sqrt() + 0.1;
    let parts: Vec<TruthMesh> = chunks
        .par_iter()
        .map(|&c| {
            let origin = DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64) * chunk_m;
            let centre = origin + DVec3::splat(0.5 * chunk_m);
            let part = if cave.eval(centre.to_array()).abs() > skip_beyond_m {
                TruthMesh::default()
            } else {
                mesh_chunk(cave, origin, cell_m, frame_from_local_m)
            };
            progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1, total);
            part
        })
        .collect();
    let mut mesh = TruthMesh::default();
    for p in parts {
        let base = mesh.positions.len() as u32;
        mesh.positions.extend(p.positions);
        mesh.normals.extend(p.normals);
        mesh.albedo.extend(p.albedo);
        mesh.triangles.extend(p.triangles.into_iter().map(|t| t.map(|i| i + base)));
    }
    mesh
}

/// One chunk's mesh: samples from one cell below `origin` to one above its far corner.
fn mesh_chunk(cave: &SynthCave, origin: DVec3, cell_m: f64, frame_from_local_m: DVec3) -> TruthMesh {
    let n = CHUNK_CELLS + 2;
    let sample = |i: u32| (f64::from(i) - 1.0) * cell_m;
    let mut sdf = vec![0f32; ChunkShape::SIZE as usize];
    for (k, v) in sdf.iter_mut().enumerate() {
        let [x, y, z] = ChunkShape::delinearize(k as u32);
        let p = origin + DVec3::new(sample(x), sample(y), sample(z));
        *v = cave.eval(p.to_array()) as f32;
    }
    let mut buf = SurfaceNetsBuffer::default();
    surface_nets(&sdf, &ChunkShape {}, [0; 3], [n - 1; 3], &mut buf);
    let mut mesh = TruthMesh::default();
    for pos in &buf.positions {
        let local =
            origin + DVec3::new(sample(0), sample(0), sample(0)) + DVec3::from(pos.map(f64::from)) * cell_m;
        // The exact normal and colour of the wall there (the crate's normals are the sampled
        // gradient; the cave gives it in closed form).
        let normal = cave.normal(local.to_array());
        let srgb = cave.color(local.to_array(), normal);
        mesh.positions.push((local + frame_from_local_m).as_vec3().to_array());
        mesh.normals.push(normal.map(|v| v as f32));
        mesh.albedo.push(srgb.map(grotto_format::color::srgb8_to_linear));
    }
    mesh.triangles = buf.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
    mesh
}

/// Writes `mesh` as binary little-endian PLY with float vertex colours `r g b` (linear albedo,
/// which Mitsuba loads as the `vertex_color` attribute) and normals.
pub fn write_ply(mesh: &TruthMesh, path: &Path) -> std::io::Result<()> {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty float r\nproperty float g\nproperty float b\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.triangles.len()
    )?;
    for i in 0..mesh.positions.len() {
        for v in mesh.positions[i].iter().chain(&mesh.normals[i]).chain(&mesh.albedo[i]) {
            out.write_all(&v.to_le_bytes())?;
        }
    }
    for t in &mesh.triangles {
        out.write_all(&[3u8])?;
        for i in t {
            out.write_all(&(*i as i32).to_le_bytes())?;
        }
    }
    out.flush()
}

/// Which light a Mitsuba scene integrates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Transport {
    /// Direct light alone (Mitsuba's `direct`: lights seen from the surface, shadowed).
    Direct,
    /// Every bounce (Mitsuba's `path`, unbounded depth, Russian roulette from the fifth).
    Full,
}

impl Transport {
    pub fn name(self) -> &'static str {
        match self {
            Transport::Direct => "direct",
            Transport::Full => "full",
        }
    }
}

/// A Mitsuba 3 scene of the mesh file `ply_name` (two-sided diffuse, albedo from its vertex
/// colours) lit by `lights` (point lights), seen by `camera` at `width` x `height`, `spp` samples
/// a pixel, box filter.
pub fn scene_xml(
    ply_name: &str,
    lights: &[SceneLight],
    camera: &Camera,
    (width, height, spp): (u32, u32, u32),
    transport: Transport,
) -> Result<String, crate::error::Error> {
    let mut s = String::from("<scene version=\"3.0.0\">\n");
    let _ = writeln!(
        s,
        "  {}",
        match transport {
            // Mitsuba's defaults: one light and one BSDF sample a camera ray (more emitter samples
            // a ray scale point lights' light by their count in Mitsuba 3.9.1, measured).
            Transport::Direct => "<integrator type=\"direct\"/>",
            Transport::Full =>
                "<integrator type=\"path\"><integer name=\"max_depth\" value=\"-1\"/></integrator>",
        }
    );
    crate::mitsuba::sensor_and_lights(&mut s, camera, (width, height, spp), lights)?;
    let _ = writeln!(
        s,
        "  <shape type=\"ply\"><string name=\"filename\" value=\"{ply_name}\"/><bsdf type=\"twosided\"><bsdf type=\"diffuse\"><texture type=\"mesh_attribute\" name=\"reflectance\"><string name=\"name\" value=\"vertex_color\"/></texture></bsdf></bsdf></shape>"
    );
    s.push_str("</scene>\n");
    Ok(s)
}
