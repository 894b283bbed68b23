// Rock behind the scanned surfaces (runtime/src/rock.rs): where cones stop.
#import scene
#import hash
#import lookup

// Rock behind the scanned surfaces (runtime/src/rock.rs, `RockTable`): a hash table of bricks of
// 4x4x4 rock cells (cells of 2x2x2 leaves). Header: capacity - 1, longest probe, bricks, 0; then
// ROCK_ENTRY_WORDS words an entry: brick x, y, z, 64 rock bits. Constants come from rock.rs
// (shaders::constants). The table lives in the lookup buffer (lookup.wgsl).

// The word offset of brick `b`'s entry (rock cells >> ROCK_BRICK_SHIFT), or EMPTY where the table
// holds none. The probe loop is bounded by the longest probe sequence the table was built with.
fn rock_entry(b: vec3<i32>) -> u32 {
    let mask = rock_word(0);
    let longest = rock_word(1);
    var slot = cell_hash(b) & mask;
    for (var i = 0u; i <= longest; i++) {
        let e = ROCK_HEADER_WORDS + slot * ROCK_ENTRY_WORDS;
        let k = vec3<i32>(bitcast<i32>(rock_word(e)), bitcast<i32>(rock_word(e + 1u)), bitcast<i32>(rock_word(e + 2u)));
        if k.x == ROCK_EMPTY_KEY {
            return EMPTY;
        }
        if all(k == b) {
            return e;
        }
        slot = (slot + 1u) & mask;
    }
    return EMPTY;
}

// The bit of rock cell `cell` in its brick `b`'s 64 bits.
fn rock_bit_index(cell: vec3<i32>, b: vec3<i32>) -> u32 {
    let l = cell - (b << vec3<u32>(ROCK_BRICK_SHIFT));
    return u32(l.x + 4 * (l.y + 4 * l.z));
}

// Whether the leaf cell holding `p_leaf` lies in rock (rock.rs, `in_rock`).
fn in_rock(p_leaf: vec3<f32>) -> bool {
    let cell = vec3<i32>(floor(p_leaf)) >> vec3<u32>(ROCK_LEVEL);
    let b = cell >> vec3<u32>(ROCK_BRICK_SHIFT);
    let e = rock_entry(b);
    if e == EMPTY {
        return false;
    }
    let bit = rock_bit_index(cell, b);
    return ((rock_word(e + 3u + bit / 32u) >> (bit % 32u)) & 1u) == 1u;
}

// The 64 rock bits of brick `b`, zero where the table holds none: a walk that stays in one brick
// for several cells reads them once (cone_rays.wgsl).
fn rock_brick_bits(b: vec3<i32>) -> vec2<u32> {
    let e = rock_entry(b);
    if e == EMPTY {
        return vec2<u32>(0u);
    }
    return vec2<u32>(rock_word(e + 3u), rock_word(e + 4u));
}

// Whether rock cell `cell` of brick `b` is set in the brick's `bits` (`rock_brick_bits`).
fn rock_bit(bits: vec2<u32>, cell: vec3<i32>, b: vec3<i32>) -> bool {
    let bit = rock_bit_index(cell, b);
    return ((bits[bit / 32u] >> (bit % 32u)) & 1u) == 1u;
}

// The first distance in (t0, t1] (metres along the cone axis) at which the axis lies in rock,
// probed once per rock cell length (at most 64 probes), or -1.
fn rock_on_segment(origin_m: vec3<f32>, dir: vec3<f32>, t0: f32, t1: f32) -> f32 {
    let cell_m = params.leaf_size_m * f32(1u << ROCK_LEVEL);
    let n = min(u32(ceil((t1 - t0) / cell_m)), 64u);
    // Probes one rock cell apart meet the same brick about three times in four: its bits are
    // looked up in the hash table once (what `in_rock` would give, probe for probe).
    var key = vec3<i32>(0x7fffffff);
    var bits = vec2<u32>(0u);
    for (var k = 1u; k <= n; k++) {
        let t = t0 + (t1 - t0) * f32(k) / f32(n);
        let cell = vec3<i32>(floor((origin_m + dir * t) / params.leaf_size_m)) >> vec3<u32>(ROCK_LEVEL);
        let b = cell >> vec3<u32>(ROCK_BRICK_SHIFT);
        if any(b != key) {
            key = b;
            bits = rock_brick_bits(b);
        }
        if rock_bit(bits, cell, b) {
            return t;
        }
    }
    return -1.0;
}
