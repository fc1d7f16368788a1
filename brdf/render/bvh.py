"""The renderer's bounding-volume hierarchy, built with numpy (the kernels in
:mod:`._intersect` traverse it).

The tree is the median split of PBR (4th ed., 7.3.1, the "equal counts" split): a node's
primitives are split at the median centroid along the axis of largest centroid extent, until
at most :data:`LEAF_SIZE` remain or their centroids coincide. The primitives are sorted by
centroid along each axis once; every node of a level is then split at once, each axis's order
partitioned stably, and the boxes are made bottom-up. Nothing to compile (a numba builder took
8 s to compile on a cold cache), and a million boxes take about 2 s, as that builder did.
"""

import numpy as np

from ._intersect import LANES, LEAF_SIZE

__all__ = ["build_bvh", "block_leaves", "LEAF_SIZE"]


def _ranges(start, count):
    """Concatenated ``arange(start[k], start[k] + count[k])``, and the offset of each range."""
    first = np.cumsum(count) - count
    return np.repeat(start - first, count) + np.arange(int(count.sum())), first


def build_bvh(lo, hi):
    """Median-split BVH over primitive boxes ``lo, hi (n, 3)``, n >= 1.

    Returns ``box (nn, 2, 3)`` (node lower and upper corners), ``child (nn, 2)`` (an inner
    node's two children; a leaf's ``(-start - 1, count)`` into ``order``) and ``order (n,)``,
    the primitives in leaf order. Node 0 is the root; nodes are numbered level by level.
    """
    lo = np.ascontiguousarray(lo, dtype=float)
    hi = np.ascontiguousarray(hi, dtype=float)
    n = lo.shape[0]
    cen = 0.5 * (lo + hi)
    # per axis, the primitives sorted by centroid within each node's range (ties by index):
    # sorted once, then split stably, so no level sorts again
    by_axis = [np.argsort(cen[:, a], kind="stable") for a in range(3)]
    left = np.zeros(n, dtype=bool)
    levels = []
    node, start, count = np.zeros(1, np.int64), np.zeros(1, np.int64), np.full(1, n, np.int64)
    next_id = 1
    while node.size:
        last = start + count - 1
        extent = np.stack([cen[by_axis[a][last], a] - cen[by_axis[a][start], a]
                           for a in range(3)], axis=1)
        axis = np.argmax(extent, axis=1)      # the first of equal extents
        split = (count > LEAF_SIZE) & (extent[np.arange(node.size), axis] > 0.0)
        child = np.empty((node.size, 2), np.int64)
        child[~split, 0], child[~split, 1] = -start[~split] - 1, count[~split]
        ids = next_id + 2 * np.arange(int(split.sum()), dtype=np.int64)
        child[split, 0], child[split, 1] = ids, ids + 1
        next_id += 2 * ids.size
        levels.append((node, child))
        # the lower half of each split node along its axis goes left; every axis's list is
        # then partitioned stably within each split node, so it stays sorted in both halves
        start, count, axis = start[split], count[split], axis[split]
        half = count // 2
        for a in range(3):
            mine = axis == a
            left[by_axis[a][_ranges(start[mine], half[mine])[0]]] = True
        pos, first = _ranges(start, count)
        seg = np.repeat(np.arange(start.size), count)
        for a in range(3):
            ids_a = by_axis[a][pos]
            goes = left[ids_a]
            before = np.cumsum(goes) - goes          # left-goers before, in the whole level
            ranks_left = before - before[first][seg]
            ranks_right = (pos - start[seg]) - ranks_left
            target = np.where(goes, start[seg] + ranks_left, start[seg] + half[seg] + ranks_right)
            by_axis[a][target] = ids_a
        left[by_axis[0][pos]] = False
        node = np.stack([ids, ids + 1], axis=1).ravel()
        start = np.stack([start, start + half], axis=1).ravel()
        count = np.stack([half, count - half], axis=1).ravel()
    order = by_axis[0].astype(np.int64)
    child = np.empty((next_id, 2), np.int64)
    for ids, c in levels:
        child[ids] = c
    # boxes bottom-up: the leaves' over their primitives, which they partition in order, then
    # each inner node's over its two children, deepest level first
    box = np.empty((next_id, 2, 3))
    leaf = np.flatnonzero(child[:, 0] < 0)
    leaf = leaf[np.argsort(-child[leaf, 0] - 1)]
    first = -child[leaf, 0] - 1
    box[leaf, 0] = np.minimum.reduceat(lo[order], first)
    box[leaf, 1] = np.maximum.reduceat(hi[order], first)
    for ids, c in reversed(levels):
        inner = c[:, 0] >= 0
        a, b = c[inner, 0], c[inner, 1]
        box[ids[inner], 0] = np.minimum(box[a, 0], box[b, 0])
        box[ids[inner], 1] = np.maximum(box[a, 1], box[b, 1])
    return box, child, order


def block_leaves(child, order, lanes=LANES):
    """The tree of :func:`build_bvh` with each leaf's primitives in blocks of ``lanes`` slots,
    the leaf pass's fixed width.

    Returns ``child`` with each leaf as ``(-first - 1, count)``, its ``count`` blocks starting
    at block ``first``, and ``slots (nb * lanes,)``: the primitive in each slot, leaf by leaf
    in the tree's order, -1 in the padding at the end of each leaf's last block.
    """
    leaf = np.flatnonzero(child[:, 0] < 0)
    start, count = -child[leaf, 0] - 1, child[leaf, 1]
    blocks = -(-count // lanes)
    first_block = np.cumsum(blocks) - blocks
    pos, first = _ranges(start, count)
    seg = np.repeat(np.arange(leaf.size), count)
    slots = np.full(int(blocks.sum()) * lanes, -1, dtype=np.int64)
    slots[first_block[seg] * lanes + np.arange(pos.size) - first[seg]] = order[pos]
    out = child.copy()
    out[leaf, 0], out[leaf, 1] = -first_block - 1, blocks
    return out, slots
