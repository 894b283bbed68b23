// The sparse voxel octree of every resident tile: finding a node, and anisotropic quadrilinear
// sampling of the radiance pyramid (light_state.wgsl).
#import scene
#import light_state
#import hash
#import lookup

struct Tile {
    origin_leaf: vec3<i32>,
    depth: u32,
    node_offset: u32,
    leaf_offset: u32,
    node_count: u32,
    leaf_count: u32,
    // 0, or the level of a coarse tile's leaves (TileGpu::leaf_lod): its SVO ends there.
    leaf_lod: u32,
    pad: array<u32, 3>,
}

struct Node {
    first_child: u32,
    mask_level: u32,
}

@group(0) @binding(1) var<storage, read> tiles: array<Tile>;
@group(0) @binding(2) var<storage, read> nodes: array<Node>;

// The tile index (runtime/src/tile_index.rs, `TileIndex`): a hash table of (cell at a tile depth,
// depth) -> tile. Header: capacity - 1, longest probe, mask of the depths entries are keyed at,
// entries, anchor x, y, z (leaf units), 0; then TILE_ENTRY_WORDS words an entry: cell x, y, z,
// depth, tile. It lives in the lookup buffer (lookup.wgsl).

// tile_index.rs `tile_hash`: the cell hash with the depth mixed in.
fn tile_hash(c: vec3<i32>, depth: u32) -> u32 {
    return cell_hash(c) ^ (depth * 0x9e3779b9u);
}

// The tile whose cube holds the leaf cell `v_leaf` (global leaf units), or EMPTY: one hash probe
// per distinct tile depth, whatever the number of tiles (tile_index.rs, `TileIndex::find`).
fn find_tile(v_leaf: vec3<i32>) -> u32 {
    let mask = tile_index_word(0);
    let longest = tile_index_word(1);
    var depths = tile_index_word(2);
    let rel = v_leaf - tile_anchor();
    while depths != 0u {
        let d = firstTrailingBit(depths);
        depths &= depths - 1u;
        let c = rel >> vec3<u32>(d);
        var slot = tile_hash(c, d) & mask;
        for (var i = 0u; i <= longest; i++) {
            let e = TILE_HEADER_WORDS + slot * TILE_ENTRY_WORDS;
            let k = vec3<i32>(bitcast<i32>(tile_index_word(e)), bitcast<i32>(tile_index_word(e + 1u)), bitcast<i32>(tile_index_word(e + 2u)));
            if k.x == TILE_EMPTY_KEY {
                break;
            }
            if all(k == c) && tile_index_word(e + 3u) == d {
                return tile_index_word(e + 4u);
            }
            slot = (slot + 1u) & mask;
        }
    }
    return EMPTY;
}

// The node covering voxel `v` of the global grid at `lod` (0 = leaves, voxel edge leaf * 2^lod),
// or EMPTY where that space is empty or outside every tile.
fn find_node(v: vec3<i32>, lod: u32) -> u32 {
    return find_node_at(v << vec3<u32>(lod), lod).x;
}

// `find_node` of the voxel at `lod` whose first leaf cell is `v_leaf` (global leaf units), with
// its tile's `leaf_lod` (0 where the node is EMPTY).
fn find_node_at(v_leaf: vec3<i32>, lod: u32) -> vec2<u32> {
    let t = find_tile(v_leaf);
    if t == EMPTY {
        return vec2<u32>(EMPTY, 0u);
    }
    let tile = tiles[t];
    if lod > tile.depth {
        return vec2<u32>(EMPTY, 0u);
    }
    // A coarse tile ends at its coarse leaves: a finer sample reads the leaf that holds it.
    let l = max(lod, tile.leaf_lod);
    let local = vec3<u32>(v_leaf - tile.origin_leaf) >> vec3<u32>(l);
    return vec2<u32>(descend(tile.node_offset, local, tile.depth - l), tile.leaf_lod);
}

// Windows of leaf cells (shade.wgsl's filters read 2 to 4 cells an axis around every pixel): the
// cells of a block 4 leaves wide on the tile index's grid share one node, found once by
// `find_node_at(first cell, BLOCK_LOD)` (for a coarse tile whose leaves are a block or wider, the
// leaf itself), and each cell's leaf is then at most two levels under it (`leaf_in_block`) instead
// of a hash probe and a descent from its tile's root. Valid when every index entry is at least 4
// leaves wide (`blocks_usable`): then a block lies in one tile, on that tile's own octree grid.
const BLOCK_LOD: u32 = 2u;

fn blocks_usable() -> bool {
    return (tile_index_word(2) & ((1u << BLOCK_LOD) - 1u)) == 0u;
}

// The tile index's anchor (leaf units): blocks are counted from it.
fn tile_anchor() -> vec3<i32> {
    return vec3<i32>(bitcast<i32>(tile_index_word(4)), bitcast<i32>(tile_index_word(5)), bitcast<i32>(tile_index_word(6)));
}

// The leaf of the cell `rel` (leaf units from the anchor) in its block `block` (`find_node_at`), or
// EMPTY: what `find_leaf` finds for that cell.
fn leaf_in_block(block: vec2<u32>, rel: vec3<i32>) -> u32 {
    var n = block.x;
    if n == EMPTY {
        return EMPTY;
    }
    if block.y < BLOCK_LOD {
        let in_block = vec3<u32>(rel & vec3<i32>(i32((1u << BLOCK_LOD) - 1u)));
        n = descend(n, in_block >> vec3<u32>(block.y), BLOCK_LOD - block.y);
        if n == EMPTY {
            return EMPTY;
        }
    }
    return nodes[n].first_child;
}

// Global leaf index of the leaf cell `v` (global leaf units), or EMPTY.
fn find_leaf(v: vec3<i32>) -> u32 {
    let n = find_node(v, 0u);
    if n == EMPTY {
        return EMPTY;
    }
    return nodes[n].first_child;
}

// `find_leaf` of the leaf cell `v`, and where that is EMPTY, a cube around `v` the lookup proved
// empty (no resident leaf in it): from `lo` (global leaf units), 2^`level` leaves wide. That is
// the node the descent found missing, or where no tile holds `v`, `v`'s cell at the tile index's
// finest depth (no entry's cube meets it: the grids of all depths are nested on the anchor's).
// For crossing empty space whole (cone_rays.wgsl, `ray_hit`).
struct LeafOrGap {
    leaf: u32,
    level: u32,
    lo: vec3<i32>,
}

fn find_leaf_or_gap(v: vec3<i32>) -> LeafOrGap {
    let t = find_tile(v);
    if t == EMPTY {
        let depths = tile_index_word(2);
        let d = select(0u, firstTrailingBit(depths), depths != 0u);
        let anchor = tile_anchor();
        return LeafOrGap(EMPTY, d, anchor + (((v - anchor) >> vec3<u32>(d)) << vec3<u32>(d)));
    }
    let tile = tiles[t];
    // As find_node_at at lod 0: a coarse tile's descent ends at its coarse leaves.
    let l = tile.leaf_lod;
    let rel = vec3<u32>(v - tile.origin_leaf);
    let local = rel >> vec3<u32>(l);
    let found = descend_or_gap(tile.node_offset, local, tile.depth - l);
    if found.x == EMPTY {
        // The missing child is 2^(found.y + l) leaves wide.
        let k = found.y + l;
        return LeafOrGap(EMPTY, k, tile.origin_leaf + vec3<i32>((rel >> vec3<u32>(k)) << vec3<u32>(k)));
    }
    return LeafOrGap(nodes[found.x].first_child, 0u, v);
}

// The node's value seen by a ray travelling along unit `dir`: its three facing directional
// values weighted by the squared direction components (the weights sum to 1).
fn directional(n: u32, dir: vec3<f32>) -> vec4<f32> {
    let w = dir * dir;
    let base = n * 6u;
    let fx = load_face(base + select(1u, 0u, dir.x >= 0.0));
    let fy = load_face(base + select(3u, 2u, dir.y >= 0.0));
    let fz = load_face(base + select(5u, 4u, dir.z >= 0.0));
    return fx * w.x + fy * w.y + fz * w.z;
}

// Descends `levels` levels from node `n` along the low bits of `local` (bit levels-1 first).
fn descend(start: u32, local: vec3<u32>, levels: u32) -> u32 {
    return descend_or_gap(start, local, levels).x;
}

// `descend`, and where it finds a child missing, which: x is the node reached or EMPTY, y the
// missing child's size, log2 of its edge in nodes of the level `levels` below `start`.
fn descend_or_gap(start: u32, local: vec3<u32>, levels: u32) -> vec2<u32> {
    var n = start;
    for (var level = 0u; level < levels; level++) {
        let b = levels - 1u - level;
        let o = ((local.x >> b) & 1u) | (((local.y >> b) & 1u) << 1u) | (((local.z >> b) & 1u) << 2u);
        let node = nodes[n];
        let mask = node.mask_level & 0xffu;
        if ((mask >> o) & 1u) == 0u {
            return vec2<u32>(EMPTY, b);
        }
        n = node.first_child + countOneBits(mask & ((1u << o) - 1u));
    }
    return vec2<u32>(n, 0u);
}

// How much of a leaf a sample at `p_leaf` sees (Settings::cone_planes): a voxel's cube stands
// up to a voxel in front of the surface it holds, so in a concave corner a cone meets the cubes
// of the wall beside it before the surface a ray would meet. Here the leaf is the half-space
// behind the plane through its surfels' centroid across its mean normal: whole at the plane and
// behind it, nothing half a leaf in front. A leaf whose normals disagree (mean shorter than 0.3:
// a thin sheet seen from both sides) keeps its cube. Mirrored by cpu_ref::leaf_plane_share.
fn leaf_plane_share(leaf_index: u32, p_leaf: vec3<f32>) -> f32 {
    let leaf = leaves[leaf_index];
    let m = leaf.normal_mean.xyz;
    let r = length(m);
    if r < 0.3 {
        return 1.0;
    }
    // center_m.w: a coarse leaf's edge (else 0).
    let edge = max(params.leaf_size_m, leaf.center_m.w);
    let ahead = dot(p_leaf * params.leaf_size_m - leaf.center_m.xyz, m / r) / edge;
    return clamp(1.0 - 2.0 * ahead, 0.0, 1.0);
}

// `leaf_plane_share` of node `n`: its leaf's for a leaf node, the mean of its leaves' for a
// parent (a leaf's cube is an eighth of it).
fn node_plane_share(n: u32, p_leaf: vec3<f32>) -> f32 {
    let node = nodes[n];
    let mask = node.mask_level & 0xffu;
    if mask == 0u {
        return leaf_plane_share(node.first_child, p_leaf);
    }
    var sum = 0.0;
    for (var o = 0u; o < 8u; o++) {
        if ((mask >> o) & 1u) == 0u {
            continue;
        }
        let c = nodes[node.first_child + countOneBits(mask & ((1u << o) - 1u))];
        sum += select(1.0, leaf_plane_share(c.first_child, p_leaf), (c.mask_level & 0xffu) == 0u);
    }
    return sum / f32(countOneBits(mask));
}

// A corner's weight in a sample: its trilinear weight, times its plane share where `planes`.
fn corner_weight(w: f32, n: u32, p_leaf: vec3<f32>, lod: u32, planes: bool) -> f32 {
    if planes && lod <= PLANE_LODS {
        return w * node_plane_share(n, p_leaf);
    }
    return w;
}

// Trilinear sample of level `lod` at `p_leaf` (leaf units from the frame origin): voxel centres
// sit at (i + 0.5) * 2^lod. Empty space contributes zero radiance and zero opacity. `planes`:
// the finest levels' nodes as half-spaces (`corner_weight`).
// The eight corners share their ancestors down to where their coordinates' bits differ, so when
// they lie in one tile the walk from the root is done once for all of them (same nodes as eight
// find_node calls, which cpu_ref.rs does).
fn sample_level(p_leaf: vec3<f32>, lod: u32, dir: vec3<f32>, planes: bool) -> vec4<f32> {
    let scale = f32(1u << lod);
    let u = p_leaf / scale - vec3<f32>(0.5);
    let base = floor(u);
    let f = u - base;
    let i0 = vec3<i32>(base);
    let t = find_tile(i0 << vec3<u32>(lod));
    let t1 = find_tile((i0 + vec3<i32>(1)) << vec3<u32>(lod));
    var acc = vec4<f32>(0.0);
    if t != EMPTY && t == t1 && lod <= tiles[t].depth && lod >= tiles[t].leaf_lod {
        let tile = tiles[t];
        let levels = tile.depth - lod;
        let lo = vec3<u32>((i0 << vec3<u32>(lod)) - tile.origin_leaf) >> vec3<u32>(lod);
        let hi = lo + vec3<u32>(1u);
        let diff = (lo ^ hi).x | (lo ^ hi).y | (lo ^ hi).z;
        let low_bits = min(32u - countLeadingZeros(diff), levels);
        let ancestor = descend(tile.node_offset, lo >> vec3<u32>(low_bits), levels - low_bits);
        if ancestor == EMPTY {
            return acc;
        }
        let mask = (1u << low_bits) - 1u;
        for (var c = 0u; c < 8u; c++) {
            let o = vec3<u32>(c & 1u, (c >> 1u) & 1u, (c >> 2u) & 1u);
            let w3 = mix(vec3<f32>(1.0) - f, f, vec3<f32>(o));
            let w = w3.x * w3.y * w3.z;
            if w <= 0.0 {
                continue;
            }
            let n = descend(ancestor, (lo + o) & vec3<u32>(mask), low_bits);
            if n != EMPTY {
                acc += corner_weight(w, n, p_leaf, lod, planes) * directional(n, dir);
            }
        }
        return acc;
    }
    for (var c = 0u; c < 8u; c++) {
        let o = vec3<u32>(c & 1u, (c >> 1u) & 1u, (c >> 2u) & 1u);
        let corner = vec3<f32>(o);
        let w3 = mix(vec3<f32>(1.0) - f, f, corner);
        let w = w3.x * w3.y * w3.z;
        if w <= 0.0 {
            continue;
        }
        let n = find_node(i0 + vec3<i32>(o), lod);
        if n != EMPTY {
            acc += corner_weight(w, n, p_leaf, lod, planes) * directional(n, dir);
        }
    }
    return acc;
}

// Quadrilinear sample: trilinear in the two levels around the fractional `lod`, blended.
fn sample_lod(p_leaf: vec3<f32>, lod: f32, dir: vec3<f32>) -> vec4<f32> {
    return sample_lod_planes(p_leaf, lod, dir, false);
}

// `sample_lod`, with the finest levels as half-spaces where `planes` (the march, under the
// `cone_planes` pipeline constant of cone.wgsl).
fn sample_lod_planes(p_leaf: vec3<f32>, lod: f32, dir: vec3<f32>, planes: bool) -> vec4<f32> {
    let l = clamp(lod, 0.0, f32(params.max_lod));
    let l0 = u32(floor(l));
    let t = l - f32(l0);
    let a = sample_level(p_leaf, l0, dir, planes);
    if t <= 0.0 || l0 >= params.max_lod {
        return a;
    }
    let b = sample_level(p_leaf, l0 + 1u, dir, planes);
    return mix(a, b, t);
}

fn outside_scene(p_leaf: vec3<f32>) -> bool {
    return any(p_leaf < params.scene_min_leaf.xyz) || any(p_leaf > params.scene_max_leaf.xyz);
}

// Whether a cone's cross-section, the ball of `radius_leaf` about `p_leaf` (leaf units), has left
// the box of the matter (params.occupied_*): the cone started inside that box and both are convex,
// so nothing ahead can meet it; only coarse levels' blur of what lies behind would (cpu_ref
// mirrors this). Radius 0: a ray.
fn cone_left_matter(p_leaf: vec3<f32>, radius_leaf: f32) -> bool {
    let gap = max(max(params.occupied_min_leaf.xyz - p_leaf, p_leaf - params.occupied_max_leaf.xyz), vec3<f32>(0.0));
    return dot(gap, gap) > radius_leaf * radius_leaf;
}
