//! Builds the spec's node-array layout from a tile's occupied leaves. This is the one place that
//! turns leaves into the level-by-level, contiguous-children array the reader checks, so the
//! preprocessor and the tests cannot drift from the spec.

use crate::spec::{MAX_SVO_DEPTH, SvoNode};

/// Node array for leaves at `depth` with the given Morton codes (3 bits per level, x lowest).
/// `leaf_mortons` must be sorted and unique (the leaf attribute arrays use the same order);
/// returns `None` otherwise, or when a code does not fit `depth`. No leaves gives no nodes.
pub fn nodes_from_leaves(leaf_mortons: &[u64], depth: u32) -> Option<Vec<SvoNode>> {
    if depth > MAX_SVO_DEPTH
        || leaf_mortons.windows(2).any(|w| w[0] >= w[1])
        || leaf_mortons.last().is_some_and(|&m| depth < MAX_SVO_DEPTH && m >> (3 * depth) != 0)
    {
        return None;
    }
    if leaf_mortons.is_empty() {
        return Some(Vec::new());
    }
    // Codes of every level, root first; each level is the sorted unique parents of the next.
    let mut levels: Vec<Vec<u64>> = vec![leaf_mortons.to_vec()];
    for _ in 0..depth {
        let mut up: Vec<u64> = levels.last().expect("non-empty").iter().map(|m| m >> 3).collect();
        up.dedup();
        levels.push(up);
    }
    levels.reverse();
    let total: usize = levels.iter().map(Vec::len).sum();
    let mut nodes = Vec::with_capacity(total);
    let mut level_start = 0usize;
    for (level, codes) in levels.iter().enumerate() {
        let next_start = level_start + codes.len();
        let children = levels.get(level + 1);
        let mut c = 0usize;
        for (i, &m) in codes.iter().enumerate() {
            let (first_child, child_mask) = match children {
                Some(children) => {
                    let first = c;
                    let mut mask = 0u8;
                    while c < children.len() && children[c] >> 3 == m {
                        mask |= 1 << (children[c] & 7);
                        c += 1;
                    }
                    ((next_start + first) as u32, mask)
                }
                None => (i as u32, 0),
            };
            nodes.push(SvoNode { morton: m, first_child, child_mask, level: level as u8, reserved: 0 });
        }
        level_start = next_start;
    }
    Some(nodes)
}

/// Interleaves the low 21 bits of x, y, z into a Morton code (x in bit 0).
pub fn morton_encode(x: u32, y: u32, z: u32) -> u64 {
    fn spread(v: u32) -> u64 {
        let mut v = u64::from(v) & 0x1f_ffff;
        v = (v | v << 32) & 0x1f_0000_0000_ffff;
        v = (v | v << 16) & 0x1f_0000_ff00_00ff;
        v = (v | v << 8) & 0x100f_00f0_0f00_f00f;
        v = (v | v << 4) & 0x10c3_0c30_c30c_30c3;
        v = (v | v << 2) & 0x1249_2492_4924_9249;
        v
    }
    spread(x) | spread(y) << 1 | spread(z) << 2
}

/// Inverse of [`morton_encode`].
pub fn morton_decode(m: u64) -> [u32; 3] {
    fn compact(mut v: u64) -> u32 {
        v &= 0x1249_2492_4924_9249;
        v = (v ^ v >> 2) & 0x10c3_0c30_c30c_30c3;
        v = (v ^ v >> 4) & 0x100f_00f0_0f00_f00f;
        v = (v ^ v >> 8) & 0x1f_0000_ff00_00ff;
        v = (v ^ v >> 16) & 0x1f_0000_0000_ffff;
        v = (v ^ v >> 32) & 0x1f_ffff;
        v as u32
    }
    [compact(m), compact(m >> 1), compact(m >> 2)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_round_trips_and_orders_x_first() {
        assert_eq!(morton_encode(1, 0, 0), 1);
        assert_eq!(morton_encode(0, 1, 0), 2);
        assert_eq!(morton_encode(0, 0, 1), 4);
        for &(x, y, z) in &[(0, 0, 0), (5, 9, 1), (0x1f_ffff, 0, 0x1f_ffff), (123_456, 654_321, 1)] {
            assert_eq!(morton_decode(morton_encode(x, y, z)), [x, y, z]);
        }
    }

    #[test]
    fn layout_has_contiguous_children() {
        // Two leaves in opposite corners of a depth-2 tile.
        let a = morton_encode(0, 0, 0);
        let b = morton_encode(3, 3, 3);
        let nodes = nodes_from_leaves(&[a, b], 2).unwrap();
        assert_eq!(nodes.len(), 5);
        assert_eq!((nodes[0].child_mask, nodes[0].first_child), (0b1000_0001, 1));
        assert_eq!((nodes[1].first_child, nodes[1].child_mask), (3, 1));
        assert_eq!((nodes[2].first_child, nodes[2].child_mask), (4, 0b1000_0000));
        assert_eq!((nodes[3].morton, nodes[3].first_child), (a, 0));
        assert_eq!((nodes[4].morton, nodes[4].first_child), (b, 1));
    }

    #[test]
    fn rejects_unsorted_and_too_deep_codes() {
        assert!(nodes_from_leaves(&[2, 1], 3).is_none());
        assert!(nodes_from_leaves(&[1, 1], 3).is_none());
        assert!(nodes_from_leaves(&[64], 2).is_none());
        assert!(nodes_from_leaves(&[0], 22).is_none());
        assert_eq!(nodes_from_leaves(&[], 4).unwrap(), vec![]);
        // Depth 0: the root is the only leaf.
        assert_eq!(nodes_from_leaves(&[0], 0).unwrap().len(), 1);
    }
}
