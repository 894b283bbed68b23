// The scene's lookup tables, in one read-only storage buffer (bind group 0): the rock table
// (rock.wgsl), the light grid (lights.wgsl) and the tile index (svo.wgsl), each at its word offset
// in `params.lookup_base` (x rock, y light grid, z tile index; renderer.rs `Upload`). One buffer,
// not three, because WebGPU's default limit is 8 storage buffers per shader stage and shade
// needs every table.
#import scene

@group(0) @binding(7) var<storage, read> lookup: array<u32>;

fn rock_word(i: u32) -> u32 {
    return lookup[params.lookup_base.x + i];
}

fn light_grid_word(i: u32) -> u32 {
    return lookup[params.lookup_base.y + i];
}

fn tile_index_word(i: u32) -> u32 {
    return lookup[params.lookup_base.z + i];
}
