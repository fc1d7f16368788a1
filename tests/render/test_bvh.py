"""The BVH builder: the tree's invariants (a partition of the primitives, boxes that hold what
is under them, splits between sorted centroids, small leaves), the root's split against a plain
SAH costing of the same candidates, closest and any hits through it (the SIMD leaf test)
against a plain numpy test of every primitive, and the wide nodes' SIMD box test against the
scalar slab test."""

import math

import numba
import numpy as np
import pytest

from brdf import render
from brdf.render import _intersect as X
from brdf.render.bvh import CANDIDATES, LEAF_SIZE, TRAVERSAL, block_leaves, build_bvh, collapse


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
def test_the_tree_is_a_partition_split_between_sorted_centroids_with_tight_boxes(n, ties):
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
        assert len(a) and len(b)
        # some axis puts every left centroid at or before every right one
        assert any(cen[a, axis].max() <= cen[b, axis].min() for axis in range(3))
    assert reached == set(range(len(box)))          # no orphan nodes


def _half_area(lo, hi):
    e = hi - lo
    return e[0] * e[1] + e[1] * e[2] + e[2] * e[0]


@pytest.mark.parametrize("n", [20, 200, 5000])
def test_the_root_split_is_the_cheapest_candidate(n):
    """The root's children are the split of least SAH cost (left count times left half area
    plus right count times right half area) among the candidates, the first
    floor(n m / k) primitives in centroid order along an axis (k = min(n, CANDIDATES)),
    costed here one by one."""
    lo, hi = _boxes(n, n)
    box, child, order = build_bvh(lo, hi)
    cen = 0.5 * (lo + hi)
    k = min(n, CANDIDATES)
    costs = {}
    for axis in range(3):
        by = np.argsort(cen[:, axis], kind="stable")
        for m in range(1, k):
            c = n * m // k
            left, right = by[:c], by[c:]
            costs[axis, m] = (c * _half_area(lo[left].min(0), hi[left].max(0))
                              + (n - c) * _half_area(lo[right].min(0), hi[right].max(0)))
    best = min(costs.values())
    if n <= LEAF_SIZE and TRAVERSAL + best / _half_area(lo.min(0), hi.max(0)) >= n:
        assert child[0, 0] < 0
        return
    a = set(order[_under(child, child[0, 0])])
    want = [set(np.argsort(cen[:, axis], kind="stable")[:n * m // k])
            for (axis, m), c in costs.items() if c <= best * (1 + 1e-9)]
    assert a in want


def test_a_million_boxes_build_in_seconds():
    import time
    lo, hi = _boxes(1_000_000, 0)
    t = time.perf_counter()
    box, child, order = build_bvh(lo, hi)
    assert time.perf_counter() - t < 30.0            # about 10 s here on a loaded host
    assert max(d for _, d in _walk(child)) <= X.DEPTH


@pytest.mark.parametrize("n, ties", [(1, False), (17, False), (2000, False), (2000, True)])
def test_leaf_blocks_hold_each_leaf_and_nothing_else(n, ties):
    lo, hi = _boxes(n, n, ties)
    box, child, order = build_bvh(lo, hi)
    blocked, slots = block_leaves(child, order, lanes=8)
    assert slots.size % 8 == 0 and sorted(slots[slots >= 0]) == list(range(n))
    for node in np.flatnonzero(child[:, 0] < 0):
        start, count = -child[node, 0] - 1, child[node, 1]
        first, blocks = -blocked[node, 0] - 1, blocked[node, 1]
        assert blocks == -(-count // 8)
        held = slots[8 * first:8 * (first + blocks)]
        # the leaf's primitives in its order, then padding to the end of its last block
        np.testing.assert_array_equal(held[:count], order[start:start + count])
        assert np.all(held[count:] == -1)
    inner = child[:, 0] >= 0
    np.testing.assert_array_equal(blocked[inner], child[inner])



def _wide_leaves(wchild, node, width):
    """The leaves (block_leaves codes) under a wide node, depth first."""
    out = []
    for s in range(width):
        c, k = wchild[node, 0, s], wchild[node, 1, s]
        if c >= 0:
            out += _wide_leaves(wchild, c, width)
        elif k > 0:
            out.append((c, k))
    return out


@pytest.mark.parametrize("width", [2, 4, 8, 16])
@pytest.mark.parametrize("n, ties", [(1, False), (17, False), (2000, False), (2000, True)])
def test_the_wide_tree_holds_each_binary_subtree_in_boxes_rounded_outward(n, ties, width):
    """Every binary node's entry (wide node and slot mask) reaches exactly its subtree's
    leaves; the float32 boxes are conservative."""
    lo, hi = _boxes(n, n, ties)
    box, child, order = build_bvh(lo, hi)
    child, _ = block_leaves(child, order)
    wbox, wchild, entry = collapse(box, child, width)
    assert wbox.dtype == np.float32 and wbox.shape == (len(wchild), 6, width)
    for node, _ in _walk(child):
        want = sorted((c, k) for c, k in (tuple(child[m]) for m, _ in _walk(child, node))
                      if c < 0)
        w, mask = entry[node]
        got = []
        for s in range(width):
            if not (mask >> s) & 1:
                continue
            c, k = wchild[w, 0, s], wchild[w, 1, s]
            got += _wide_leaves(wchild, c, width) if c >= 0 else ([(c, k)] if k > 0 else [])
        assert sorted(got) == want      # the node's mask covers its leaves and no others
    # an empty slot's box is +inf (no ray enters it); a leaf's holds its float64 box, rounded
    # outward by at most one float32 unit in the last place
    for w in range(len(wchild)):
        for s in range(width):
            if wchild[w, 1, s] == 0 and wchild[w, 0, s] < 0:
                assert np.all(np.isinf(wbox[w, :, s]))
    leaf_of = {tuple(child[m]): m for m in np.flatnonzero(child[:, 0] < 0)}
    for w in range(len(wchild)):
        for s in range(width):
            c, k = wchild[w, 0, s], wchild[w, 1, s]
            if c < 0 and k > 0:
                b = box[leaf_of[(c, k)]]
                lo32, hi32 = wbox[w, 0:3, s].astype(float), wbox[w, 3:6, s].astype(float)
                assert np.all(lo32 <= b[0]) and np.all(hi32 >= b[1])
                assert np.all(b[0] - lo32 <= 2 ** -23 * np.abs(b[0]))
                assert np.all(hi32 - b[1] <= 2 ** -23 * np.abs(b[1]))


@numba.njit
def _wide_entries(wbox, n, o, r, tmax, dist):
    return X._wide_entries(wbox, n, o[0], o[1], o[2], r[0], r[1], r[2], tmax, dist)


@numba.njit
def _slab_entries(wbox, n, o, r, tmax, dist):
    for s in range(wbox.shape[2]):
        corners = ((float(wbox[n, 0, s]), float(wbox[n, 1, s]), float(wbox[n, 2, s])),
                   (float(wbox[n, 3, s]), float(wbox[n, 4, s]), float(wbox[n, 5, s])))
        near, enters = X._slab(corners, o[0], o[1], o[2], r[0], r[1], r[2], tmax)
        dist[s] = near if enters else math.inf


def test_a_wide_nodes_simd_box_test_is_the_scalar_slab_test_to_the_bit():
    """The SIMD test of a wide node's children (an LLVM vector intrinsic) gives the scalar
    slab test's entry distances bit for bit, and its mask marks the children entered, also
    where the scalar test meets NaN: rays parallel to an axis (reciprocal +-inf) starting on
    a box's face, flat boxes, empty slots (+inf boxes), a finite tmax."""
    rng = np.random.default_rng(11)
    nodes = 400
    lo = rng.uniform(-1, 1, (nodes, 3, X.WIDTH))
    hi = lo + rng.uniform(0, 1, (nodes, 3, X.WIDTH)) * (rng.random((nodes, 3, X.WIDTH)) < 0.8)
    wbox = np.concatenate([lo, hi], axis=1).astype(np.float32)
    wbox[rng.random(nodes) < 0.1, :, 0] = np.inf                     # empty slots
    got, want = np.empty(X.WIDTH), np.empty(X.WIDTH)
    entered = 0
    for k in range(4000):
        n = k % nodes
        o = rng.uniform(-2, 2, 3)
        # towards a child's centre (most enter it), or anywhere
        d = (0.5 * (lo[n, :, k % X.WIDTH] + hi[n, :, k % X.WIDTH]) - o if k % 4 == 1
             else rng.normal(size=3))
        d[rng.random(3) < 0.25] = 0.0                                  # parallel to axes
        d /= max(np.linalg.norm(d), 1e-300)
        with np.errstate(divide="ignore"):
            r = 1.0 / d
        if k % 3 == 0:                                                 # on a face or an edge
            axes = rng.random(3) < 0.5
            o[axes] = wbox[n, np.flatnonzero(axes) + 3 * (k % 2), 0]
        tmax = math.inf if k % 2 else rng.uniform(0, 3)
        mask = _wide_entries(wbox, n, o, r, tmax, got)
        _slab_entries(wbox, n, o, r, tmax, want)
        assert got.tobytes() == want.tobytes()
        assert mask == sum(1 << s for s in range(X.WIDTH) if want[s] != math.inf)
        entered += mask != 0
    assert 500 < entered < 3500      # both outcomes, many times each


def _reference_hit(shapes, o, d):
    """(t, shape, face) of the nearest hit, plain numpy: Moller-Trumbore on each triangle, the
    quadratic on the sphere, the plane and edge coordinates on the rectangle."""
    best = (math.inf, -1, -1)
    mesh, sphere, rect = shapes
    v = mesh.vertices[mesh.faces]
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    p = np.cross(d, e2)
    det = np.sum(e1 * p, axis=1)
    s = o - v[:, 0]
    b1 = np.sum(s * p, axis=1) / det
    q = np.cross(s, e1)
    b2 = q @ d / det
    t = np.sum(e2 * q, axis=1) / det
    ok = (b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1) & (t > 0)
    if ok.any():
        k = np.flatnonzero(ok)[np.argmin(t[ok])]
        best = (t[k], 0, k)
    f = o - np.asarray(sphere.centre)
    b = f @ d
    disc = b * b - (f @ f - sphere.radius ** 2)
    if disc >= 0:
        for t in (-b - math.sqrt(disc), -b + math.sqrt(disc)):
            if 0 < t < best[0]:
                best = (t, 1, 0)
                break
    c, u, w = np.asarray(rect.corner), np.asarray(rect.edge1), np.asarray(rect.edge2)
    n = np.cross(u, w)
    t = (c - o) @ n / (d @ n)
    if 0 < t < best[0]:
        h = o + t * d - c
        a, bb = np.linalg.lstsq(np.stack([u, w], axis=1), h, rcond=None)[0]
        if 0 <= a <= 1 and 0 <= bb <= 1:
            best = (t, 2, 0)
    return best


def _trace(geo, o, d, tmax, any_hit, n=X.PACKET):
    """One packet through the tree: rays (PACKET, 3) from o along d, lanes with tmax < 0 idle,
    the first n traced; returns the rows (t, slot) trace_packet leaves."""
    ray = np.ascontiguousarray(np.concatenate([o, d], axis=1).T)
    t = np.array(tmax, dtype=float)
    hit = np.empty(X.PACKET, dtype=np.int64)
    X.trace_packet(geo, np.empty(2 * X.STACK, dtype=np.int64), np.empty(X.LANES), ray,
                   np.empty((3, X.PACKET)), np.empty(X.PACKET, dtype=np.int64), t, hit, any_hit,
                   n)
    return t, hit


@pytest.mark.parametrize("spread", [0.02, 2.0])
def test_packets_find_the_hits_of_every_primitive(spread):
    """Packets of nearly parallel rays (traversed as packets) and of scattered ones (which part
    ways and go on alone), idle lanes among them: nearest hits, the hit's coordinates, and any
    hit within the nearest one's distance or just short of it, against plain numpy."""
    rng = np.random.default_rng(3)
    m = 300
    centres = rng.uniform(-1, 1, (m, 3))
    vertices = (centres[:, None, :] + 0.15 * rng.standard_normal((m, 3, 3))).reshape(-1, 3)
    shapes = [render.Mesh(vertices, np.arange(3 * m).reshape(m, 3)),
              render.Sphere((0.2, 0.1, 0.0), 0.3),
              render.rectangle(np.diag([0.5, 0.5, 1.0, 1.0]))]
    geo = render.Scene(shapes=shapes).compile().geo
    prim, sph, quad, tri, tri_n, tri_uv, box, child, slots, planes = geo[:10]
    hits = 0
    for _ in range(8):
        o = rng.uniform(-3, 3, 3) + spread * rng.standard_normal((X.PACKET, 3))
        # towards points of the soup, most rays hit
        d = np.clip(rng.uniform(-1, 1, 3) + spread * rng.standard_normal((X.PACKET, 3)), -1, 1) - o
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        idle = rng.random(X.PACKET) < 0.1
        t, slot = _trace(geo, o, d, np.where(idle, -1.0, math.inf), False)
        want = [_reference_hit(shapes, o[j], d[j]) for j in range(X.PACKET)]
        seen = np.array([w[1] >= 0 and not idle[j] for j, w in enumerate(want)])
        np.testing.assert_array_equal(slot >= 0, seen)
        _, blocked = _trace(geo, o, d, np.where(idle, -1.0, math.inf), True)
        np.testing.assert_array_equal(blocked >= 0, seen)
        short = np.where(seen, t * (1 - 1e-9), -1.0)
        _, blocked = _trace(geo, o, d, short, True, n=X.PACKET - 8)   # the lanes the integrator
        assert not (blocked[:X.PACKET - 8] >= 0).any()  # traces: nothing before the nearest hit
        for j in np.flatnonzero(seen):
            want_t, shape, face = want[j]
            i = slots[slot[j]]
            hits += 1
            kinds = (X.TRIANGLE, X.SPHERE, X.QUAD)
            assert prim[i, 0] == kinds[shape] and (shape != 0 or prim[i, 1] == face)
            assert t[j] == pytest.approx(want_t, rel=1e-12)
            # the hit's (a, b) are the triangle's barycentrics, or the rectangle's coordinates
            a, b = X.plane_coordinates(planes, slot[j], *o[j], *d[j], t[j])
            hit = o[j] + t[j] * d[j]
            if shape == 0:
                v = vertices[3 * face:3 * face + 3]
                np.testing.assert_allclose(v[0] + a * (v[1] - v[0]) + b * (v[2] - v[0]), hit,
                                           atol=1e-12)
            elif shape == 2:
                np.testing.assert_allclose(quad[prim[i, 1], 0] + a * quad[prim[i, 1], 1]
                                           + b * quad[prim[i, 1], 2], hit, atol=1e-12)
    assert hits > 150


_MASKED_STORES = """
import json
import numpy as np
from brdf.render import builtin, rays, _intersect as X
compiled = builtin("cornell").compile()
o, d = np.zeros((8, 3)), np.tile([0.0, 0.0, -1.0], (8, 1))
rays.first_hits(compiled, o, d)
rays.occluded(compiled, o, d, np.full(8, np.inf))
print(json.dumps([c.library.get_llvm_str().count("call void @llvm.masked.store")
                  for c in X.trace_packet.overloads.values()]))
"""


def test_the_packet_loops_vectorise_without_masked_stores(tmp_path):
    """The packet traversal's loops over its lanes (a primitive's closest-hit test, the
    any-hit lanes' ending) store whole vectors: LLVM had written their updates of tmax as
    masked stores, which AMD's Zen 3 cores run in microcode (the Cornell box's render 1.25x
    slower on znver3). Checked in the optimised LLVM IR of a fresh compile, so on any host
    with AVX. (The integrator's shading batches were rid of one too, in ``_vertices``; they
    compile only within the renderer's kernel, too slow a compile for this check.)"""
    import json
    import os
    import subprocess
    import sys
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"),
           "NUMBA_CACHE_LOCATOR_CLASSES": "UserProvidedCacheLocator"}
    done = subprocess.run([sys.executable, "-c", _MASKED_STORES], env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    counts = json.loads(done.stdout.splitlines()[-1])
    assert counts == [0], counts


def test_a_scene_compiled_again_reuses_its_tree_and_a_moved_one_does_not():
    """The same boxes give the same tree (kept, not built again); a moved shape gets its own,
    whose root box holds it where it now is."""
    def scene(x):
        return render.Scene(shapes=[render.Sphere((x, 0.0, 0.0), 0.5),
                                    render.rectangle(np.diag([0.5, 0.5, 1.0, 1.0]))])
    a, b, moved = scene(0.3).compile().geo, scene(0.3).compile().geo, scene(7.0).compile().geo
    assert a.box is b.box and a.child is b.child and a.slots is b.slots
    assert moved.box is not a.box
    assert moved.box[0, 1, 0] >= 7.5 and a.box[0, 1, 0] < 1.0
