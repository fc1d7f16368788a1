"""The BVH builder: the tree's invariants (a partition of the primitives, boxes that hold what
is under them, equal-count splits along the widest centroid axis, small leaves) and closest hits
through it against a brute-force test of every primitive."""

import math

import numpy as np
import pytest

from brdf import render
from brdf.render import _intersect as X
from brdf.render.bvh import LEAF_SIZE, build_bvh


def _boxes(n, seed, ties=False):
    rng = np.random.default_rng(seed)
    c = rng.random((n, 3))
    if ties:
        c = np.round(c * 3) / 3          # many primitives share a centroid
    r = 0.05 * rng.random((n, 3))
    return c - r, c + r


def _walk(child, node=0, depth=0):
    """(node, depth) of every node, depth first."""
    yield node, depth
    if child[node, 0] >= 0:
        for c in child[node]:
            yield from _walk(child, c, depth + 1)


def _under(child, node):
    """Primitive positions (into order) under a node."""
    if child[node, 0] < 0:
        start = -child[node, 0] - 1
        return np.arange(start, start + child[node, 1])
    return np.concatenate([_under(child, c) for c in child[node]])


@pytest.mark.parametrize("n, ties", [(1, False), (3, False), (5, False), (200, False),
                                     (2000, False), (2000, True)])
def test_the_tree_is_a_median_split_partition_with_tight_boxes(n, ties):
    lo, hi = _boxes(n, n, ties)
    box, child, order = build_bvh(lo, hi)
    assert sorted(order) == list(range(n))
    cen = 0.5 * (lo + hi)
    reached = set()
    for node, _ in _walk(child):
        reached.add(node)
        prims = order[_under(child, node)]
        # the node's box is exactly the union of its primitives' boxes
        np.testing.assert_array_equal(box[node, 0], lo[prims].min(axis=0))
        np.testing.assert_array_equal(box[node, 1], hi[prims].max(axis=0))
        extent = np.ptp(cen[prims], axis=0)
        if child[node, 0] < 0:
            assert len(prims) <= LEAF_SIZE or extent.max() == 0.0
            continue
        a, b = (order[_under(child, c)] for c in child[node])
        assert len(a) == len(prims) // 2 and len(b) == len(prims) - len(prims) // 2
        axis = int(np.argmax(extent))
        assert cen[a, axis].max() <= cen[b, axis].min()
    assert reached == set(range(len(box)))          # no orphan nodes


def test_a_million_boxes_build_in_seconds():
    import time
    lo, hi = _boxes(1_000_000, 0)
    t = time.perf_counter()
    box, child, order = build_bvh(lo, hi)
    assert time.perf_counter() - t < 30.0            # about 2 s here, as the numba builder was
    assert max(d for _, d in _walk(child)) <= math.ceil(math.log2(1_000_000 / LEAF_SIZE)) + 1


def test_closest_hits_through_the_tree_are_those_of_every_primitive():
    rng = np.random.default_rng(3)
    m = 300
    centres = rng.uniform(-1, 1, (m, 3))
    vertices = (centres[:, None, :] + 0.15 * rng.standard_normal((m, 3, 3))).reshape(-1, 3)
    shapes = [render.Mesh(vertices, np.arange(3 * m).reshape(m, 3)),
              render.Sphere((0.2, 0.1, 0.0), 0.3),
              render.rectangle(np.diag([0.5, 0.5, 1.0, 1.0]))]
    geo = render.Scene(shapes=shapes).compile().geo
    prim, sph, quad, tri, tri_n, tri_uv, box, child, order = geo
    stack = np.empty(X.STACK, dtype=np.int64)
    flat_child = np.array([[-1, len(prim)]])        # one leaf holding every primitive
    flat_box = np.array([[[-1e9] * 3, [1e9] * 3]])
    flat_order = np.arange(len(prim))
    hits = 0
    for _ in range(400):
        o = rng.uniform(-3, 3, 3)
        d = rng.uniform(-1, 1, 3) - o               # towards the soup, most rays hit
        d /= np.linalg.norm(d)
        got = X.closest_hit(prim, sph, quad, tri, box, child, order, stack, *o, *d, math.inf)
        want = X.closest_hit(prim, sph, quad, tri, flat_box, flat_child, flat_order, stack,
                             *o, *d, math.inf)
        assert got[1] == want[1]
        if want[1] >= 0:
            hits += 1
            assert got[0] == want[0]
    assert hits > 200
