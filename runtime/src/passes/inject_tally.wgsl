// After a light edit in place, inject's last batch left each re-injected leaf's relative change of
// direct light in `pending.w`: this gathers the largest per tile (and overall) into the bounce's
// change buffer, so that only the tiles whose direct light changed start the bounces
// (runtime/src/light/activity.rs `end_edit`), not every tile within the edited lights' range.
// Its own pass because inject binds as many storage buffers as WebGPU allows one stage by default.
#import activity
#import dispatch

@compute @workgroup_size(64)
fn tally(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let k = linear_index(gid, nwg);
    if k >= active_tiles.item_count {
        return;
    }
    let item = active_leaf(k);
    let change = leaf_light[item.x].pending.w;
    // A change that is not a number counts as a change (as in propagate).
    let bits = select(bitcast<u32>(change), 0x7f7fffffu, change != change);
    atomicMax(&changes.max_change_bits, bits);
    atomicMax(&changes.tiles[item.y], bits);
}
