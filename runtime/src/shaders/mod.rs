//! WGSL sources and the small import mechanism that composes them.
//!
//! Shared WGSL lives in `shaders/`, one file per subsystem (scene, light state, SVO, rock, cone
//! tracing, lights, SH, colour, packing, ...); each pass's WGSL lives beside its module in
//! `passes/`. A file names what it needs with `#import name` lines (names of `shaders/` files);
//! [`compose`] puts each needed file in once, dependencies first, after the constants generated
//! from Rust ([`constants`]). A pass therefore declares only the bindings of the subsystems it
//! imports, and its bind group layouts are reflected from that (passes/mod.rs).

use crate::error::{Error, Result};

/// The shared library: (import name, source).
pub(crate) const LIBRARY: &[(&str, &str)] = &[
    ("active", include_str!("active.wgsl")),
    ("activity", include_str!("activity.wgsl")),
    ("brdf", include_str!("brdf.wgsl")),
    ("color", include_str!("color.wgsl")),
    ("cone", include_str!("cone.wgsl")),
    ("cone_batch", include_str!("cone_batch.wgsl")),
    ("cone_rays", include_str!("cone_rays.wgsl")),
    ("dispatch", include_str!("dispatch.wgsl")),
    ("geometry", include_str!("geometry.wgsl")),
    ("hash", include_str!("hash.wgsl")),
    ("light_state", include_str!("light_state.wgsl")),
    ("lights", include_str!("lights.wgsl")),
    ("lookup", include_str!("lookup.wgsl")),
    ("ndf", include_str!("ndf.wgsl")),
    ("packing", include_str!("packing.wgsl")),
    ("rock", include_str!("rock.wgsl")),
    ("scene", include_str!("scene.wgsl")),
    ("sh", include_str!("sh.wgsl")),
    ("svo", include_str!("svo.wgsl")),
];

pub(crate) const ENV: &str = include_str!("../passes/env.wgsl");
pub(crate) const INJECT: &str = include_str!("../passes/inject.wgsl");
pub(crate) const INJECT_TALLY: &str = include_str!("../passes/inject_tally.wgsl");
pub(crate) const MIP: &str = include_str!("../passes/mip.wgsl");
pub(crate) const PROPAGATE: &str = include_str!("../passes/propagate.wgsl");
pub(crate) const TAIL: &str = include_str!("../passes/tail.wgsl");
pub(crate) const SPLAT: &str = include_str!("../passes/splat.wgsl");
/// Presents a frame in a window or a browser's canvas (present.rs).
pub(crate) const PRESENT: &str = include_str!("../render/present.wgsl");
pub(crate) const SHADE: &str = include_str!("../passes/shade.wgsl");
pub(crate) const RESOLVE: &str = include_str!("../passes/resolve.wgsl");
pub(crate) const EXPOSE: &str = include_str!("../passes/expose.wgsl");
pub(crate) const REBASE: &str = include_str!("../passes/rebase.wgsl");

/// Constants shared with the Rust side, generated from it so the two cannot drift.
pub(crate) fn constants() -> String {
    use crate::gpu::types::{LightShadow, flags};
    use crate::scene::{rock, tile_index};
    let mut out = format!(
        "const EMPTY: u32 = 0xffffffffu;\nconst ROCK_LEVEL: u32 = {}u;\nconst ROCK_BRICK_SHIFT: u32 = {}u;\n\
         const ROCK_HEADER_WORDS: u32 = {}u;\nconst ROCK_ENTRY_WORDS: u32 = {}u;\nconst ROCK_EMPTY_KEY: i32 = {};\n",
        rock::ROCK_LEVEL,
        rock::BRICK_SHIFT,
        rock::HEADER_WORDS,
        rock::ENTRY_WORDS,
        // WGSL has no literal for i32::MIN (its negation overflows): write it as an expression.
        format_args!("({} - 1)", rock::EMPTY_KEY + 1),
    );
    out += &format!(
        "const TILE_HEADER_WORDS: u32 = {}u;\nconst TILE_ENTRY_WORDS: u32 = {}u;\nconst TILE_EMPTY_KEY: i32 = ({} - 1);\n",
        tile_index::HEADER_WORDS,
        tile_index::ENTRY_WORDS,
        tile_index::EMPTY_KEY + 1,
    );
    for (name, bit) in flags::ALL {
        out += &format!("const {name}: u32 = {bit}u;\n");
    }
    out += &format!("const FLAG_VIEWS_WITHOUT_LIGHT: u32 = {}u;\n", flags::VIEWS_WITHOUT_LIGHT);
    out += &format!("const PLANE_LODS: u32 = {}u;\n", crate::gpu::types::PLANE_LODS);
    out += &cone_rays_constants();
    out += &format!("const NO_SCAN: u32 = {}u;\n", crate::gpu::types::NO_SCAN);
    // The level a coarse tile's leaves are held at (coarse.rs): the level view tells coarse from far.
    out += &format!("const COARSE_LEVELS: u32 = {}u;\n", crate::scene::coarse::COARSE_LEVELS);
    out += &crate::view::lux::wgsl();
    for kind in LightShadow::ALL {
        out += &format!("const {}: u32 = {}u;\n", kind.wgsl_name(), kind as u32);
    }
    out
}

/// gpu/types.rs `cone_rays` as WGSL `RAY_*` constants.
fn cone_rays_constants() -> String {
    use crate::gpu::types::cone_rays as r;
    let pattern: Vec<String> = r::PATTERN.iter().map(|[x, y]| format!("vec2<f32>({x:?}, {y:?})")).collect();
    format!(
        "const RAY_LIFT_LEAVES: f32 = {:?};\nconst RAY_PLANE_OFFSET_LEAVES: f32 = {:?};\n\
         const RAY_MIN_RISE: f32 = {:?};\nconst RAY_COUNT: u32 = {}u;\n\
         const RAY_PATTERN = array<vec2<f32>, {}>({});\n",
        r::LIFT_LEAVES,
        r::PLANE_OFFSET_LEAVES,
        r::MIN_RISE,
        r::PATTERN.len(),
        r::PATTERN.len(),
        pattern.join(", "),
    )
}

/// The names a source imports (its `#import name` lines), in order.
fn imports(src: &str) -> impl Iterator<Item = &str> {
    src.lines().filter_map(|l| l.trim().strip_prefix("#import ")).map(str::trim)
}

/// The generated constants, then every library file `src` needs (dependencies first, each once),
/// then `src` itself; `#import` lines become comments.
pub fn compose(src: &str) -> Result<String> {
    fn visit(name: &str, order: &mut Vec<&'static str>, stack: &mut Vec<String>) -> Result<()> {
        let Some(&(known, text)) = LIBRARY.iter().find(|(n, _)| *n == name) else {
            return Err(Error::Internal {
                what: "WGSL import",
                message: format!("no shader named '{name}'"),
            });
        };
        if order.contains(&known) {
            return Ok(());
        }
        if stack.iter().any(|s| s == name) {
            return Err(Error::Internal {
                what: "WGSL import",
                message: format!("import cycle: {} -> {name}", stack.join(" -> ")),
            });
        }
        stack.push(name.to_owned());
        for dep in imports(text) {
            visit(dep, order, stack)?;
        }
        stack.pop();
        order.push(known);
        Ok(())
    }
    let mut order = Vec::new();
    for dep in imports(src) {
        visit(dep, &mut order, &mut Vec::new())?;
    }
    let strip = |text: &str| -> String {
        text.lines()
            .map(|l| if l.trim().starts_with("#import ") { format!("// {}", l.trim()) } else { l.to_owned() })
            .collect::<Vec<_>>()
            .join("\n")
    };
    let mut out = constants();
    for name in order {
        let text = LIBRARY.iter().find(|(n, _)| *n == name).map_or("", |(_, t)| t);
        out += &format!("\n// ---- shaders/{name}.wgsl\n{}\n", strip(text));
    }
    out += &format!("\n// ---- pass\n{}\n", strip(src));
    Ok(out)
}

/// (name, source) of every shader module the runtime creates, before composing.
pub(crate) const PASSES: [(&str, &str); 11] = [
    ("env", ENV),
    ("expose", EXPOSE),
    ("inject", INJECT),
    ("inject_tally", INJECT_TALLY),
    ("mip", MIP),
    ("propagate", PROPAGATE),
    ("rebase", REBASE),
    ("resolve", RESOLVE),
    ("shade", SHADE),
    ("splat", SPLAT),
    ("tail", TAIL),
];

/// (name, complete module source) of every shader module the runtime creates.
pub fn all() -> Result<Vec<(&'static str, String)>> {
    PASSES.iter().map(|(name, src)| Ok((*name, compose(src)?))).collect()
}
