//! CPU/GPU struct layouts agree: every struct the WGSL shares with `gpu/types.rs` has the same
//! size and every member the same offset on both sides (naga reflection of the composed modules,
//! no GPU). Sizes alone (asserted in gpu/types.rs) would miss two swapped members.

use std::collections::BTreeMap;
use std::mem::offset_of;

use grotto_runtime::gpu::types::*;

/// Size and (field, offset) list of a Rust struct.
type RustLayout = (usize, Vec<(&'static str, usize)>);

/// The [`RustLayout`] of a struct.
macro_rules! rust_layout {
    ($t:ty { $($f:ident),* $(,)? }) => {
        (size_of::<$t>(), vec![$((stringify!($f), offset_of!($t, $f))),*])
    };
}

/// Every struct of every composed module, by name: (span, [(member, offset)]).
fn wgsl_structs() -> BTreeMap<String, (u32, Vec<(String, u32)>)> {
    let mut out = BTreeMap::new();
    for (name, src) in grotto_runtime::shaders::all().unwrap() {
        let module = naga::front::wgsl::parse_str(&src).unwrap_or_else(|e| panic!("{name}: {e}"));
        for (_, ty) in module.types.iter() {
            if let (Some(n), naga::TypeInner::Struct { members, span }) = (&ty.name, &ty.inner) {
                let m = members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset)).collect();
                out.insert(n.clone(), (*span, m));
            }
        }
    }
    out
}

/// Members whose WGSL form differs from Rust's: WGSL name -> (Rust field, byte offset in it).
/// (A `[u32; 3]` cannot be an array in a uniform struct, whose arrays have 16-byte strides.)
const ALIASES: [(&str, &str, usize); 3] = [
    ("light_grid_x", "light_grid_dims", 0),
    ("light_grid_y", "light_grid_dims", 4),
    ("light_grid_z", "light_grid_dims", 8),
];

/// Differences between a WGSL struct and its Rust mirror, in words.
fn compare(wgsl: &(u32, Vec<(String, u32)>), rust: &RustLayout) -> Vec<String> {
    let mut problems = Vec::new();
    if wgsl.0 as usize != rust.0 {
        problems.push(format!("size: WGSL {} bytes, Rust {}", wgsl.0, rust.0));
    }
    let rust_fields: BTreeMap<&str, usize> = rust.1.iter().copied().collect();
    let mut seen = Vec::new();
    for (member, offset) in &wgsl.1 {
        let (field, within) =
            ALIASES.iter().find(|a| a.0 == member).map_or((member.as_str(), 0), |a| (a.1, a.2));
        match rust_fields.get(field) {
            None => problems.push(format!("WGSL member '{member}' has no Rust field")),
            Some(&o) => {
                if o + within != *offset as usize {
                    problems.push(format!("'{member}': WGSL offset {offset}, Rust {}", o + within));
                }
                seen.push(field);
            }
        }
    }
    for (field, _) in &rust.1 {
        if !seen.contains(field) {
            problems.push(format!("Rust field '{field}' is not in the WGSL struct"));
        }
    }
    problems
}

/// Every shared struct: WGSL name and its Rust layout.
fn shared() -> Vec<(&'static str, RustLayout)> {
    vec![
        (
            "Tile",
            rust_layout!(TileGpu {
                origin_leaf,
                depth,
                node_offset,
                leaf_offset,
                node_count,
                leaf_count,
                leaf_lod,
                pad
            }),
        ),
        ("Node", rust_layout!(NodeGpu { first_child, mask_level })),
        ("Leaf", rust_layout!(LeafGpu { albedo_opacity, normal_mean, center_m, emission })),
        ("LeafLight", rust_layout!(LeafLightGpu { direct, gather, out, env, far, pending, residual, tail })),
        ("Light", rust_layout!(LightGpu { position_kind, intensity_layer, direction_cos_outer, params })),
        (
            "Params",
            rust_layout!(Params {
                leaf_size_m,
                tile_count,
                leaf_count,
                light_count,
                cone_count,
                cone_tan_half,
                step_scale,
                max_distance_m,
                max_steps,
                max_lod,
                shadow_size,
                flags,
                width,
                height,
                exposure,
                shadow_bias_m,
                shadow_cols,
                light_grid_dims,
                light_grid_min_m,
                scene_min_leaf,
                scene_max_leaf,
                occupied_min_leaf,
                occupied_max_leaf,
                background,
                camera_eye_m,
                camera_forward,
                camera_right,
                camera_up,
                cones,
                env_sh,
                materials,
                env_levels,
                env_chain,
                lookup_base,
                tail_ratio_max,
            }),
        ),
        ("MipRange", rust_layout!(MipRange { first, count, height, pad })),
        ("InjectBatch", rust_layout!(InjectBatch { first, count, reset, last })),
        ("ConeBatch", rust_layout!(ConeBatch { first, count, pad0, pad1 })),
        ("ActiveTile", rust_layout!(ActiveTile { tile, first_leaf, leaf_count, first_item })),
        (
            "Splat",
            rust_layout!(SplatUniform { view_proj, eye_m, viewport, splat, clip_min_m, clip_max_m, pad }),
        ),
    ]
}

#[test]
fn every_shared_struct_has_the_same_layout_on_both_sides() {
    let wgsl = wgsl_structs();
    let mut problems = Vec::new();
    for (name, rust) in shared() {
        match wgsl.get(name) {
            None => problems.push(format!("{name}: not in any WGSL module")),
            Some(w) => problems.extend(compare(w, &rust).into_iter().map(|p| format!("{name}: {p}"))),
        }
    }
    assert!(problems.is_empty(), "{problems:#?}");
}

#[test]
fn the_comparison_sees_swapped_members_and_missing_fields() {
    // The check itself must be able to fail: a WGSL struct with two members swapped, and one
    // with a member Rust lacks, are both reported.
    let rust = rust_layout!(MipRange { first, count, height, pad });
    let swapped =
        (16, vec![("count".into(), 0), ("first".into(), 4), ("height".into(), 8), ("pad".into(), 12)]);
    assert_eq!(compare(&swapped, &rust).len(), 2);
    let extra =
        (16, vec![("first".into(), 0), ("count".into(), 4), ("height".into(), 8), ("spare".into(), 12)]);
    let p = compare(&extra, &rust);
    assert!(p.iter().any(|p| p.contains("'spare'")) && p.iter().any(|p| p.contains("'pad'")), "{p:?}");
}
