// Hashing integer cells for the GPU's open-addressing tables (rock bricks, the tile index).

// rock.rs `brick_hash`: each axis times a large odd constant (Teschner et al. 2003), xor-ed, then
// murmur3's finaliser so neighbouring cells spread over the table.
fn cell_hash(b: vec3<i32>) -> u32 {
    var h = (u32(b.x) * 0x8da6b343u) ^ (u32(b.y) * 0xd8163841u) ^ (u32(b.z) * 0xcb1ab31fu);
    h ^= h >> 16u;
    h *= 0x85ebca6bu;
    h ^= h >> 13u;
    h *= 0xc2b2ae35u;
    return h ^ (h >> 16u);
}
