"""Derivative images: the derivatives of every pixel in a material's parameters, estimated by
the same paths as the image (:func:`brdf.render.render` with ``derivatives=``).

>>> from brdf import render, parse
>>> model = parse("lambert(albedo=0.5) + ggx(alpha=0.3)")
>>> scene = render.builtin("sphere", model)
>>> d = render.Derivatives(model, ["ggx.alpha", "lambert.albedo"])
>>> r = render.render(scene, spp=4, size=(32, 32), derivatives=d, progress=False)
>>> r.derivatives.shape  # (h, w, RGB, one image per parameter)
(32, 32, 3, 2)

The paths are drawn as on ``material`` (the proposal), and f on its surfaces is evaluated with
the parameters of ``evaluate`` (default: ``material`` itself). With the same seed, the image is
then a smooth function of ``evaluate``'s parameters (detached sampling: the directions, the
light samples, the MIS weights and the ends of the paths do not move with them), and the
derivative images are exactly its derivatives; both are unbiased for the image and its
derivatives at those parameters. Russian roulette is off in such renders (it would end paths on
the evaluated throughput), so a path runs to ``max_depth`` unless it leaves the scene.
"""

from dataclasses import dataclass

import numpy as np

from ..arguments import shown
from ..errors import InputError

__all__ = ["Derivatives"]


@dataclass(frozen=True)
class Derivatives:
    """Which derivative images a render also estimates.

    Attributes
    ----------
    material : Model
        The model object on the scene's shapes whose parameters the images follow (every shape
        that holds this object; its sampling is the proposal's).
    parameters : sequence
        One entry per derivative image: a flat parameter name (``"ggx.alpha"``; a per-channel
        parameter's ``"lambert.albedo[1]"`` one channel, ``"lambert.albedo"`` all of them
        together; a single lobe's names may omit its own), or an array of positions in the
        packed parameters (``material.compile(3).params``) that move together.
    evaluate : Model, optional
        A model with the same lobes whose parameters f is evaluated with on those surfaces.
    """

    material: object
    parameters: tuple
    evaluate: object = None

    def slots(self):
        """``(K, S)`` packed positions of each image's parameters, -1 padding each row."""
        from ..models.base import Model
        if not isinstance(self.material, Model):
            raise InputError(f"render: derivatives: material must be a model, got "
                             f"{type(self.material).__name__}")
        params = self.parameters
        if isinstance(params, (str, bytes)) or not len(params):
            raise InputError(f"render: derivatives: parameters must be a non-empty list of "
                             f"names or slot arrays, got {shown(params)}")
        layout = self.material.compile(3)
        size = len(layout.params)
        rows = [self._slots_of(p, layout, size) for p in params]
        out = np.full((len(rows), max(len(r) for r in rows)), -1, dtype=np.int64)
        for k, r in enumerate(rows):
            out[k, :len(r)] = r
        return out

    def _slots_of(self, p, layout, size):
        if not isinstance(p, str):
            r = np.asarray(p).ravel()
            if not (r.size and np.issubdtype(r.dtype, np.integer) and r.min() >= 0
                    and r.max() < size):
                raise InputError(f"render: derivatives: slots must be integers in [0, {size}), "
                                 f"got {shown(p)}")
            return r.astype(np.int64)
        base, _, rest = p.partition("[")
        channel = None
        if rest:
            if not (rest.endswith("]") and rest[:-1].isdigit()):
                raise InputError(f"render: derivatives: expected NAME or NAME[CHANNEL], got "
                                 f"{p!r}")
            channel = int(rest[:-1])
        lobes = self.material.lobes
        names = self.material.lobe_names() if len(lobes) > 1 else [lobes[0].name]
        lobe, _, pname = base.rpartition(".")
        if not lobe and len(lobes) == 1:
            lobe = names[0]
        found = (layout.slots[names.index(lobe)].get(pname) if lobe in names else None)
        if found is None:
            known = [f"{n}.{k}" for n, s in zip(names, layout.slots) for k in s]
            raise InputError(f"render: derivatives: {p!r} is not a parameter of "
                             f"{self.material}; one of {', '.join(known)}")
        if channel is None:
            return np.concatenate(found)
        if channel >= len(found):
            raise InputError(f"render: derivatives: {p!r}: {base} has {len(found)} "
                             f"channel{'s' if len(found) > 1 else ''}")
        return np.asarray(found[channel])

    def check(self, compiled):
        """``(target, evaluate)``: the rows of ``compiled.mats`` of :attr:`material` and of
        the model f is evaluated with (``compiled``'s one extra material); :class:`InputError` when the material is on no shape,
        the two differ in lobes, or a lobe is a delta lobe."""
        from ..models import _kernels
        from ._materials import K0, K1, O0, O1, TYPE, MODEL, B0, B1
        target = compiled.material_index(self.material)
        if target is None:
            raise InputError(f"render: derivatives: no shape of the scene holds the material "
                             f"{self.material} (the same model object)")
        ev = compiled.extra[0]
        mint, kinds, offs = compiled.mats.mint, compiled.mats.kinds, compiled.mats.offs
        for m in (target, ev):
            if mint[m, TYPE] != MODEL:
                raise InputError(f"render: derivatives: {self.material} renders as a table "
                                 "(custom lobes); derivatives need the families' kernels")
            if mint[m, B1] > mint[m, B0]:
                raise InputError("render: derivatives: the material is textured; derivative "
                                 "images follow one parameter vector")
        lobes = [kinds[mint[m, K0]:mint[m, K1]].tolist() for m in (target, ev)]
        layouts = [offs[mint[m, O0]:mint[m, O1]].tolist() for m in (target, ev)]
        if lobes[0] != lobes[1] or layouts[0] != layouts[1]:
            raise InputError(f"render: derivatives: evaluate ({self.evaluate}) must have the "
                             f"lobes and layout of the material ({self.material})")
        if any(_kernels.is_delta(k) for k in lobes[0]):
            raise InputError(f"render: derivatives: {self.material} has a delta lobe, whose "
                             "reflectance the paths cannot differentiate")
        return target, ev
