// A leaf's normal distribution (Toksvig): its mean normal vector, whose length says how much the
// normals agree, and the frames and cosines built from it.
#import scene
#import geometry

// Unit mean normal of a leaf, or +z where its normals cancel (no preferred side).
fn leaf_normal(mean: vec3<f32>) -> vec3<f32> {
    let r = length(mean);
    if r < 1e-4 {
        return vec3<f32>(0.0, 0.0, 1.0);
    }
    return mean / r;
}

// Cosine term averaged over a leaf's normal distribution, for a light in direction `l`. The mean
// of n . l over the normals is mean . l = r c, exact wherever every normal faces the light: a
// leaf on a face, or in a concave corner of a room lit from inside it. The second term keeps a
// leaf whose normals cancel (r = 0: a thin sheet seen from both sides) lit at a quarter, the
// mean clamped cosine of normals spread over the sphere, and fades as (1 - r)^2 so a leaf whose
// normals only mostly agree gains almost nothing. The mixture it replaced, r of the clamped
// cosine and 1 - r of (1 + c) / 4, counted the spread of a leaf on a room's edge (two faces,
// r = 0.71) as normals pointing at the lamp: +25% on those leaves, +3% on the scanned dogleg's
// lit room (docs/reference.md, "Judged on scans").
fn ndf_cos(mean: vec3<f32>, l: vec3<f32>) -> f32 {
    let r = min(length(mean), 1.0);
    let c = dot(leaf_normal(mean), l);
    return r * max(c, 0.0) + 0.25 * (1.0 - r) * (1.0 - r);
}

// A leaf's cones start one leaf off its surface, so that a cone does not see its own leaf first.
fn leaf_cone_lift(leaf: Leaf) -> f32 {
    // center_m.w: the leaf's edge where it is a coarse leaf wider than the package's (else 0).
    return max(params.leaf_size_m, leaf.center_m.w);
}

fn leaf_cone_origin(leaf: Leaf) -> vec3<f32> {
    return leaf.center_m.xyz + leaf_normal(leaf.normal_mean.xyz) * leaf_cone_lift(leaf);
}

// Height of a leaf's cone origin above its surface and the rise per metre along `dir`
// (`trace_cone`'s `rise`).
fn leaf_cone_rise(leaf: Leaf, dir: vec3<f32>) -> vec2<f32> {
    return vec2<f32>(leaf_cone_lift(leaf), dot(dir, leaf_normal(leaf.normal_mean.xyz)));
}

// World direction of a cone given in the leaf's tangent frame (z = mean normal), turned about the
// normal by the leaf's interleave angle (`cone_interleave_rad`).
fn leaf_cone_dir(leaf: Leaf, local: vec3<f32>) -> vec3<f32> {
    let phi = cone_interleave_rad(leaf);
    let c = cos(phi);
    let s = sin(phi);
    let turned = vec3<f32>(c * local.x - s * local.y, s * local.x + c * local.y, local.z);
    return normalize(basis(leaf_normal(leaf.normal_mean.xyz)) * turned);
}

// Interleaved sampling (Keller & Heidrich 2001): a fixed cone set has a fixed azimuth in every
// leaf whose normal points the same way, so where it misses (a corridor between two cones) it
// misses on the whole wall, and the error is a bias no filter removes. Turning the set by one of
// eight angles by the parity of the leaf's cell makes every 2x2x2 block hold eight different
// sets, which shading averages (passes/shade.wgsl: the tent twice as wide under trilinear, the
// B-spline under tricubic) and the next bounce's mip too.
fn cone_interleave_rad(leaf: Leaf) -> f32 {
    if (params.flags & FLAG_CONE_INTERLEAVE) == 0u {
        return 0.0;
    }
    let cell = vec3<i32>(floor(leaf.center_m.xyz / params.leaf_size_m));
    let k = (cell.x & 1) + 2 * (cell.y & 1) + 4 * (cell.z & 1);
    return f32(k) * 0.7853981634;
}
