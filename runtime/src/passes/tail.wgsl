// The end of a propagation bounce, once it has run every leaf of the active tiles: each leaf's
// tail (the estimated gather of the bounces not run, `Settings::bounce_tail`) and the change the
// bounce made to what the leaf shows, for the effect plan (largest over all leaves) and for the
// choice of the next bounce's tiles (largest per tile). One workgroup per active tile.
//
// The bounces not run, per channel, as the rest of a geometric series: once the light is spread,
// each bounce changes the gather by the same ratio r of the one before (the dominant eigenvalue of
// one bounce), and the changes still to come add up to residual * r / (1 - r) (Aitken's
// extrapolation). r is the tile's: the sum of its settling leaves' residuals over the sum of
// their bounce before's, a leaf settling where its own ratio lies in 0..=1 (where it is above 1,
// light is still arriving, as in a corridor's far end, and its changes would raise the ratio of
// the leaves beside it that are settling). A leaf's own ratio of two small, differently shaped
// changes scatters widely, and r / (1 - r) turns that scatter into overshoot (convex in r): on
// the colour box the tail after three bounces came out 0.031 (relative RMSE over the leaves) from
// sixteen bounces with a ratio per leaf, 0.005 with one per tile (docs/runtime.md, "The bounce
// tail"). The series itself
// runs on without the tail (out and the pyramid hold the bounces run), so successive changes stay
// those of plain propagation; only what a surface shows adds it (shade, and the change that
// decides convergence: once the estimate stops moving, more bounces would not change the image).
// A tile ratio above the scene's largest albedo (params.tail_ratio_max; zero without the tail)
// gets the largest ratio trusted, and none from 1 on.
//
// propagate.wgsl left, per leaf: residual = this bounce's change, pending = the bounce before's,
// out = the new outgoing radiance, tail = the old tail less the residual (so out + albedo * tail
// is what the leaf showed before this bounce).
#import activity

const TAIL_GROUP: u32 = 256u;

var<workgroup> sum_residual: array<vec3<f32>, TAIL_GROUP>;
var<workgroup> sum_last: array<vec3<f32>, TAIL_GROUP>;
var<workgroup> largest: array<f32, TAIL_GROUP>;

@compute @workgroup_size(TAIL_GROUP)
fn tail(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let k = wid.x + wid.y * nwg.x;
    if k >= active_tiles.tile_count {
        return;
    }
    let t = active_tiles.tiles[k];
    var res = vec3<f32>(0.0);
    var last = vec3<f32>(0.0);
    for (var j = li; j < t.leaf_count; j += TAIL_GROUP) {
        let s = leaf_light[t.first_leaf + j];
        let settling = leaf_settling(s.residual.rgb, s.pending.rgb);
        res += select(vec3<f32>(0.0), s.residual.rgb, settling);
        last += select(vec3<f32>(0.0), s.pending.rgb, settling);
    }
    sum_residual[li] = res;
    sum_last[li] = last;
    workgroupBarrier();
    for (var half = TAIL_GROUP / 2u; half > 0u; half /= 2u) {
        if li < half {
            sum_residual[li] += sum_residual[li + half];
            sum_last[li] += sum_last[li + half];
        }
        workgroupBarrier();
    }
    let r = tile_ratio(sum_residual[0], sum_last[0]);
    let grow = r / (1.0 - r);
    var change = 0.0;
    for (var j = li; j < t.leaf_count; j += TAIL_GROUP) {
        let i = t.first_leaf + j;
        let leaf = leaves[i];
        var state = leaf_light[i];
        let before = leaf_shown(leaf, state);
        state.tail = vec4<f32>(state.residual.rgb * grow, 0.0);
        let after = leaf_shown(leaf, state);
        leaf_light[i] = state;
        let scale = max(max(after.r, max(after.g, after.b)), 1e-6);
        let diff = abs(after - before);
        change = max(change, max(diff.r, max(diff.g, diff.b)) / scale);
    }
    largest[li] = change;
    workgroupBarrier();
    for (var half = TAIL_GROUP / 2u; half > 0u; half /= 2u) {
        if li < half {
            largest[li] = max(largest[li], largest[li + half]);
        }
        workgroupBarrier();
    }
    if li == 0u {
        atomicMax(&changes.max_change_bits, bitcast<u32>(largest[0]));
        atomicMax(&changes.tiles[t.tile], bitcast<u32>(largest[0]));
    }
}

// The ratio of a tile's summed residual to the bounce before's, per channel, as trusted
// (LeafLightGpu::tile_ratio on the CPU): where it lies in 0..=1 (as a settling leaf's own,
// `leaf_settling`), at most params.tail_ratio_max; else 0.
fn tile_ratio(residual: vec3<f32>, last: vec3<f32>) -> vec3<f32> {
    let ratio = residual / select(vec3<f32>(1.0), last, abs(last) > vec3<f32>(1e-20));
    return select(vec3<f32>(0.0), min(ratio, params.tail_ratio_max.rgb), leaf_settling(residual, last));
}

// Per channel, whether a leaf's own ratio (this bounce's residual over the bounce before's) lies in
// 0..=1: its light is settling rather than still arriving (LeafLightGpu::settling on the CPU).
fn leaf_settling(residual: vec3<f32>, last: vec3<f32>) -> vec3<bool> {
    let ok = abs(last) > vec3<f32>(1e-20);
    let own = residual / select(vec3<f32>(1.0), last, ok);
    return ok & (own >= vec3<f32>(0.0)) & (own <= vec3<f32>(1.0));
}
