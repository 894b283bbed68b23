// Anisotropic mipmapping, one dispatch per node height (0 = leaves), deepest first. Leaves get six
// equal values (opacity * radiance, opacity); an inner node composites its children front to back
// along each travel direction (premultiplied alpha) and averages the four columns.
#import svo
#import dispatch

struct MipRange {
    first: u32,
    count: u32,
    height: u32,
    pad: u32,
}

@group(2) @binding(0) var<uniform> range: MipRange;
// Global node indices ordered by height.
@group(2) @binding(1) var<storage, read> by_height: array<u32>;

// Value of child octant `o` of `node` for face `f`, zero where the child is absent.
fn child_face(node: Node, o: u32, f: u32) -> vec4<f32> {
    let mask = node.mask_level & 0xffu;
    if ((mask >> o) & 1u) == 0u {
        return vec4<f32>(0.0);
    }
    let c = node.first_child + countOneBits(mask & ((1u << o) - 1u));
    return load_face(c * 6u + f);
}

@compute @workgroup_size(64)
fn mip(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let k = linear_index(gid, nwg);
    if k >= range.count {
        return;
    }
    let n = by_height[range.first + k];
    let node = nodes[n];
    if range.height == 0u {
        let leaf = node.first_child;
        let a = leaves[leaf].albedo_opacity.a;
        let v = vec4<f32>(leaf_light[leaf].out.rgb * a, a);
        for (var f = 0u; f < 6u; f++) {
            store_face(n * 6u + f, v);
        }
        return;
    }
    for (var f = 0u; f < 6u; f++) {
        let axis = f / 2u;
        let positive = (f & 1u) == 0u;
        let bit = 1u << axis;
        var sum = vec4<f32>(0.0);
        for (var o = 0u; o < 8u; o++) {
            if (o & bit) != 0u {
                continue;
            }
            // o is the low child of its column along `axis`; the ray enters low first when it
            // travels toward +axis.
            let low = child_face(node, o, f);
            let high = child_face(node, o | bit, f);
            let front = select(high, low, positive);
            let back = select(low, high, positive);
            sum += front + (1.0 - front.a) * back;
        }
        store_face(n * 6u + f, sum * 0.25);
    }
}
