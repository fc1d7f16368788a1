"""Point location in Delaunay triangulations for the scattered-data interpolation of tables.

Kept out of :mod:`brdf.table` so that importing the package does not import numba.
"""

import numpy as np

from ._jit import kernel

__all__ = ["Simplices"]


class Simplices:
    """Point location in a Delaunay triangulation, fast for many queries.

    scipy's ``find_simplex`` walks from the same simplex for every query (about 0.1 ms per
    query for 10^4 samples in 3-D); here each walk starts at the simplex whose centroid is
    nearest to the query (a KD-tree), so it takes a few steps.
    """

    #: A coordinate that varies less than this over the samples is constant (e.g. the
    #: out-of-plane one of an in-plane scan): the triangulation drops it.
    FLAT = 1e-9
    #: Steps a walk may take before qhull's own search takes over.
    MAX_STEPS = 200

    def __init__(self, points, method):
        from scipy.spatial import Delaunay, cKDTree
        self.varying = np.ptp(points, axis=0) > self.FLAT
        self.constant = points[0, ~self.varying]
        points = np.ascontiguousarray(points[:, self.varying])
        # samples that all sit at one place (a single sample, say) vary along no coordinate:
        # every query's nearest sample is then the first
        self.nearest = cKDTree(points) if points.shape[1] else None
        self.delaunay = None
        self.line = None
        if method == "linear" and points.shape[1] == 1 and len(points) > 1:
            # qhull needs 2-D; on a line the simplices are the intervals between sorted points
            self.line = np.argsort(points[:, 0], kind="stable")
            self.sorted_x = points[self.line, 0]
        elif method == "linear" and len(points) > points.shape[1] + 1:
            self.delaunay = Delaunay(points, qhull_options="QJ Qbb")
            self.centroids = cKDTree(points[self.delaunay.simplices].mean(axis=1))
            self.transform = _barycentric_transforms(self.delaunay.points,
                                                     self.delaunay.simplices)
            self.low = points.min(axis=0) - 1e-12
            self.high = points.max(axis=0) + 1e-12
            self.neighbors = np.ascontiguousarray(self.delaunay.neighbors, dtype=np.int64)

    def locate(self, q):
        """``(vertex indices (n, k), weights (n, k), inside (n,))`` for points ``q`` (n, d).

        Queries off the samples' constant coordinates are located by the varying ones and
        reported as outside (extrapolated).
        """
        on_flat = np.all(np.abs(q[:, ~self.varying] - self.constant) <= 1e-6, axis=1)
        q = np.ascontiguousarray(q[:, self.varying])
        vertices, weights, inside = self._locate(q)
        return vertices, weights, inside & on_flat

    def _locate(self, q):
        n, d = q.shape
        if self.line is not None:
            return self._locate_on_line(q[:, 0])
        if self.nearest is None:
            return np.zeros((n, 1), np.intp), np.ones((n, 1)), np.ones(n, dtype=bool)
        if self.delaunay is None:
            _, idx = self.nearest.query(q)
            return idx[:, None], np.ones((n, 1)), np.ones(n, dtype=bool)
        simplex = np.full(n, -1, dtype=np.int64)
        bary = np.zeros((n, d + 1))
        # a query outside the samples' bounding box is outside the hull: no walk needed
        box = np.all((q >= self.low) & (q <= self.high), axis=1)
        rows = np.nonzero(box)[0]
        if len(rows):
            _, start = self.centroids.query(q[rows])
            found = np.empty(len(rows), dtype=np.int64)
            b = np.empty((len(rows), d + 1))
            _walk(self.transform, self.neighbors, np.asarray(start, np.int64),
                  np.ascontiguousarray(q[rows]), self.MAX_STEPS, found, b)
            simplex[rows], bary[rows] = found, b
            # walks that ran out of steps (around flat simplices) ask qhull instead
            stuck = rows[found == -2]
            if len(stuck):
                s = self.delaunay.find_simplex(q[stuck])
                simplex[stuck] = s
                ok = s >= 0
                bary[stuck[ok]] = self._barycentric(s[ok], q[stuck[ok]])
        inside = simplex >= 0
        vertices = np.zeros((n, d + 1), dtype=np.intp)
        vertices[inside] = self.delaunay.simplices[simplex[inside]]
        if not inside.all():
            _, idx = self.nearest.query(q[~inside])
            vertices[~inside, 0] = idx
            bary[~inside] = 0.0
            bary[~inside, 0] = 1.0
        return vertices, bary, inside


    def _barycentric(self, simplex, q):
        """Barycentric coordinates (n, d + 1) of points q in the given simplices."""
        t = self.transform[simplex]
        d = q.shape[1]
        b = np.einsum("nij,nj->ni", t[:, :d, :], q - t[:, d, :])
        return np.concatenate([b, 1.0 - b.sum(axis=1, keepdims=True)], axis=1)

    def _locate_on_line(self, x):
        xs = self.sorted_x
        right = np.clip(np.searchsorted(xs, x), 1, len(xs) - 1)
        left = right - 1
        span = xs[right] - xs[left]
        w = np.clip((x - xs[left]) / np.where(span > 0, span, 1.0), 0.0, 1.0)
        inside = (x >= xs[0]) & (x <= xs[-1])
        vertices = np.stack([self.line[left], self.line[right]], axis=1)
        return vertices, np.stack([1.0 - w, w], axis=1), inside


def _barycentric_transforms(points, simplices):
    """scipy's ``Delaunay.transform`` for every simplex at once: rows ``:d`` hold T^-1, where
    T's columns are the edges r_j - r_d, and row ``d`` holds r_d, so the barycentric
    coordinates of x are T^-1 (x - r_d) (scipy.spatial.Delaunay docs). scipy builds them one
    simplex at a time (two minutes for the 6e5 simplices of 2e4 samples in 4-D; this takes a
    second). Numerically flat simplices get NaN, as in scipy (reciprocal condition number
    below 100 machine epsilons)."""
    v = points[simplices]
    d = v.shape[2]
    t = np.swapaxes(v[:, :d, :] - v[:, d:, :], 1, 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        flat = ~(1.0 / np.linalg.cond(t) >= 100.0 * np.finfo(float).eps)
    t[flat] = np.eye(d)
    out = np.empty((len(v), d + 1, d))
    out[:, :d, :] = np.linalg.inv(t)
    out[:, d, :] = v[:, d, :]
    out[flat] = np.nan
    return out


@kernel
def _walk(transform, neighbors, start, q, max_steps, simplex, bary):
    """Visibility walk (Devillers, Pion & Teillaud 2002, "Walking in a triangulation", sec. 2):
    from ``start``, step to the neighbour opposite the most negative barycentric coordinate
    until all are >= 0 (found), that neighbour is -1 (outside the hull: simplex -1), or
    ``max_steps`` are used (simplex -2: undecided)."""
    n, d = q.shape
    for k in range(n):
        s = start[k]
        simplex[k] = -2
        for _ in range(max_steps):
            total = 0.0
            worst, worst_j = 0.0, -1
            flat = False
            for j in range(d):
                b = 0.0
                for m in range(d):
                    b += transform[s, j, m] * (q[k, m] - transform[s, d, m])
                # qhull leaves NaN in the transform of a numerically flat simplex
                flat = flat or b != b
                bary[k, j] = b
                total += b
                if b < worst:
                    worst, worst_j = b, j
            if flat:
                break
            bary[k, d] = 1.0 - total
            if bary[k, d] < worst:
                worst, worst_j = bary[k, d], d
            # a point on a shared face may read -1e-15 on both sides: accept it
            if worst >= -1e-12:
                simplex[k] = s
                break
            s = neighbors[s, worst_j]
            if s < 0:
                simplex[k] = -1
                break
