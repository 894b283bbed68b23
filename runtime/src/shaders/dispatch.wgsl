// 1D workloads dispatched as 2D grids of 64-wide groups.

// Item index of a 1D workload dispatched as a 2D grid of 64-wide groups (dispatches are limited
// to 65535 groups per dimension). Keep in sync with passes::dispatch_linear.
fn linear_index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 64u;
}
