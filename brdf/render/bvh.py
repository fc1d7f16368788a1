"""The renderer's bounding-volume hierarchy, built with numpy (the kernels in
:mod:`._intersect` traverse it).

A node's primitives are split where the surface area heuristic (SAH; Goldsmith and Salmon 1987,
MacDonald and Booth 1990; PBR 4th ed., 7.3.2) is least: the expected cost of a split, a node
visit plus each side's primitives times its share of the node's surface area, against testing
the node's primitives in a leaf. As in binned SAH builders (Wald 2007, "On fast construction of
SAH-based bounding volume hierarchies"), only a few candidates are costed: along each axis, at
:data:`CANDIDATES` evenly spaced ranks of the node's centroids. A node becomes a leaf when no
candidate costs less than the leaf and it holds at most :data:`LEAF_SIZE` primitives, or when
its centroids coincide. The primitives are sorted by centroid along each axis once; every node
of a level is then costed and split at once, each axis's order partitioned stably, and the
boxes are made bottom-up. Nothing to compile (a numba builder took 8 s to compile on a cold
cache).
"""

import numpy as np

from ._intersect import DEPTH, LANES, LEAF_SIZE, WIDTH

#: Split candidates costed per node and axis (at most; a node of fewer primitives costs
#: every split).
CANDIDATES = 32
#: A node visit's cost in primitive tests, in the SAH. A leaf's primitives are tested side by
#: side in SIMD lanes, so a test costs little against a visit: on the 40,400-triangle sphere of
#: ``bench_render.py``, one thread, rays per second against the median split (camera, bounce,
#: shadow rays): 2 and 4 built deeper trees that were slower or no faster; 8 to 16 were 20-27 %
#: faster.
TRAVERSAL = 12.0

__all__ = ["build_bvh", "block_leaves", "collapse", "LEAF_SIZE"]


def _ranges(start, count):
    """Concatenated ``arange(start[k], start[k] + count[k])``, and the offset of each range."""
    first = np.cumsum(count) - count
    return np.repeat(start - first, count) + np.arange(int(count.sum())), first


def _running(fn, x, seg, nseg, reverse=False):
    """``fn.accumulate`` (np.minimum or np.maximum) down the rows of ``x (m, 3)`` within each
    run of equal ``seg`` (0 .. nseg - 1, ascending), from the end if ``reverse``. Each run is
    shifted past the ones before it so that they cannot reach it (the shifts round the values
    off by about nseg units in the last place: enough for costing splits)."""
    big = 2.0 * float(np.max(np.abs(x))) + 1.0
    sign = 1.0 if fn is np.maximum else -1.0
    if reverse:
        off = (sign * big * (nseg - 1 - seg[::-1]))[:, None]
        return (fn.accumulate(x[::-1] + off, axis=0) - off)[::-1]
    off = (sign * big * seg)[:, None]
    return fn.accumulate(x + off, axis=0) - off


def _half_area(lo, hi):
    e = hi - lo
    return e[:, 0] * e[:, 1] + e[:, 1] * e[:, 2] + e[:, 2] * e[:, 0]


def _sah_splits(lo, hi, by_axis, start, count):
    """For each node (``start, count`` into the orders ``by_axis``): the axis and left count of
    its cheapest candidate split, that split's SAH cost (the sides' counts times their half
    areas) and the node's half area. A candidate splits after a chunk: a node's sorted
    primitives fall into min(count, CANDIDATES) chunks of nearly equal length, whose boxes
    are reduced at once and then run together from either end."""
    nseg = start.size
    pos, first = _ranges(start, count)
    k = np.minimum(count, CANDIDATES)
    kstart = np.cumsum(k) - k
    owner = np.repeat(np.arange(nseg), k)
    m = np.arange(int(k.sum())) - kstart[owner]
    chunk = (count[owner] * m) // k[owner]          # each chunk's first rank in its node
    nleft = np.zeros_like(chunk)
    nleft[:-1] = chunk[1:]
    last = m == k[owner] - 1
    cost = np.empty((3, chunk.size))
    for a in range(3):
        ids = by_axis[a][pos]
        # np.take: four times faster than indexing rows with an array (numpy 2.x)
        clo = np.minimum.reduceat(np.take(lo, ids, axis=0), first[owner] + chunk, axis=0)
        chi = np.maximum.reduceat(np.take(hi, ids, axis=0), first[owner] + chunk, axis=0)
        left = _half_area(_running(np.minimum, clo, owner, nseg),
                          _running(np.maximum, chi, owner, nseg))
        rlo = _running(np.minimum, clo, owner, nseg, True)
        rhi = _running(np.maximum, chi, owner, nseg, True)
        right = np.zeros_like(left)
        right[:-1] = _half_area(rlo[1:], rhi[1:])
        cost[a] = np.where(last, np.inf, nleft * left + (count[owner] - nleft) * right)
        if a == 0:
            area = _half_area(rlo[kstart], rhi[kstart])
    least = np.stack([np.minimum.reduceat(cost[a], kstart) for a in range(3)])
    axis = np.argmin(least, axis=0)
    best = least[axis, np.arange(nseg)]
    # the first chunk of the best axis that reaches it
    at = np.where(np.take(cost, axis[owner] * chunk.size + np.arange(chunk.size)) == best[owner],
                  m, CANDIDATES)
    at = np.minimum(np.minimum.reduceat(at, kstart), k - 1)
    return axis, nleft[kstart + at], best, area


def build_bvh(lo, hi):
    """SAH-split BVH over primitive boxes ``lo, hi (n, 3)``, n >= 1.

    Returns ``box (nn, 2, 3)`` (node lower and upper corners), ``child (nn, 2)`` (an inner
    node's two children; a leaf's ``(-start - 1, count)`` into ``order``) and ``order (n,)``,
    the primitives in leaf order. Node 0 is the root; nodes are numbered level by level. Below
    depth DEPTH - log2(n) nodes are split at their median centroid along the widest axis,
    so that no path from the root is longer than DEPTH (the traversal's stack bound).
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
    median_from = DEPTH - int(np.ceil(np.log2(max(n, 2))))
    while node.size:
        last = start + count - 1
        extent = np.stack([cen[by_axis[a][last], a] - cen[by_axis[a][start], a]
                           for a in range(3)], axis=1)
        apart = extent.max(axis=1) > 0.0
        if len(levels) < median_from:
            axis, half, best, area = _sah_splits(lo, hi, by_axis, start, count)
            split = apart & ((count > LEAF_SIZE)
                             | (TRAVERSAL + best / np.maximum(area, 1e-300) < count))
        else:
            axis, half = np.argmax(extent, axis=1), count // 2      # the first of equal extents
            split = apart & (count > LEAF_SIZE)
        child = np.empty((node.size, 2), np.int64)
        child[~split, 0], child[~split, 1] = -start[~split] - 1, count[~split]
        ids = next_id + 2 * np.arange(int(split.sum()), dtype=np.int64)
        child[split, 0], child[split, 1] = ids, ids + 1
        next_id += 2 * ids.size
        levels.append((node, child))
        # the first half of each split node along its axis goes left; every axis's list is
        # then partitioned stably within each split node, so it stays sorted in both halves
        start, count, axis, half = start[split], count[split], axis[split], half[split]
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


def _outward(x, toward):
    """``x`` (float64) as float32, rounded toward ``toward`` (-inf or inf) where it is not
    exact, so that a float32 box holds its float64 box."""
    f = x.astype(np.float32)
    off = (f < x) if toward > 0 else (f > x)
    return np.where(off, np.nextafter(f, np.float32(toward)), f)


def collapse(box, child, width=WIDTH):
    """The tree of :func:`block_leaves` (``box, child``) as a ``width``-wide tree (a power of
    two), for single rays: each wide node holds the nodes ``log2(width)`` levels below one
    binary node, the binary tree's levels in between dropped (Dammertz et al. 2008, "Shallow
    Bounding Volume Hierarchies for Fast SIMD Ray Tracing of Incoherent Rays"; Wald et al.
    2008, "Getting Rid of Packets"), so that one node visit tests ``width`` boxes side by side
    in SIMD lanes. The SAH tree it collapses is :func:`build_bvh`'s.

    Returns ``wbox (nw, 6, width)`` float32: each child slot's lower then upper corner, a row
    per coordinate (structure of arrays), rounded outward from the binary tree's float64 boxes;
    an empty slot's is +inf everywhere, which no ray enters. ``wchild (nw, 2, width)``: a
    slot's wide node (row 0, >= 0, row 1 zero), or its leaf as ``block_leaves`` codes it
    (``-first - 1`` and the block count); an empty slot holds a leaf of no blocks. ``entry
    (nn, 2)``: for each binary node, the wide node whose slots cover its subtree and the bit
    mask of those slots (a packet that leaves a binary node to its rays starts them there).
    Node 0 is the root; a wide node's subtree never holds more levels than the binary one's.
    """
    k = int(width).bit_length() - 1
    if width < 2 or 1 << k != width:
        raise ValueError(f"width {width}: expected a power of two >= 2")
    nn = child.shape[0]
    entry = np.zeros((nn, 2), np.int64)
    lo = _outward(box[:, 0], -np.inf)
    hi = _outward(box[:, 1], np.inf)
    roots, base = np.zeros(1, np.int64), 0
    wboxes, wchildren = [], []
    while roots.size:
        m = roots.size
        wid = base + np.arange(m, dtype=np.int64)
        cur = roots[:, None]
        for i in range(k + 1):
            span = width >> i
            pos = np.arange(cur.shape[1], dtype=np.int64)
            mask = ((1 << span) - 1) << (pos * span)
            valid = cur >= 0
            rows = np.broadcast_to(wid[:, None], cur.shape)[valid]
            entry[cur[valid], 0] = rows
            entry[cur[valid], 1] = np.broadcast_to(mask, cur.shape)[valid]
            if i == k:
                break
            safe = np.maximum(cur, 0)
            inner = valid & (child[safe, 0] >= 0)
            nxt = np.empty((m, 2 * cur.shape[1]), np.int64)
            nxt[:, 0::2] = np.where(inner, child[safe, 0], cur)
            nxt[:, 1::2] = np.where(inner, child[safe, 1], -1)
            cur = nxt
        # cur (m, width): each slot's binary node, -1 where empty
        safe = np.maximum(cur, 0)
        valid = cur >= 0
        inner = valid & (child[safe, 0] >= 0)
        nxt_roots = cur[inner]
        wc = np.zeros((m, 2, width), np.int64)
        wc[:, 0] = -1
        wc[:, 0][inner] = base + m + np.arange(nxt_roots.size, dtype=np.int64)
        leaf = valid & ~inner
        wc[:, 0][leaf] = child[cur[leaf], 0]
        wc[:, 1][leaf] = child[cur[leaf], 1]
        wb = np.full((m, 6, width), np.inf, np.float32)
        wb[:, 0:3] = np.where(valid[:, None], lo[safe].transpose(0, 2, 1), np.float32(np.inf))
        wb[:, 3:6] = np.where(valid[:, None], hi[safe].transpose(0, 2, 1), np.float32(np.inf))
        wboxes.append(wb)
        wchildren.append(wc)
        base += m
        roots = nxt_roots
    return np.concatenate(wboxes), np.concatenate(wchildren), entry
