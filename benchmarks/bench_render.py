"""Path-tracing throughput on a suite of scenes against Mitsuba 3, in the same run.

Run: ``python benchmarks/bench_render.py [--scene NAME ...] [--all] [--size 256] [--spp 64]
[--depth 8] [--repeats 5] [--layers] [--stages]`` (without ``--scene`` or ``--all``: the
Cornell box)

Each scene is written once, as a neutral description (:data:`SCENES`: camera, shapes with a
material spec, lights, environment), and built from it for both renderers at the same size,
samples per pixel and maximum depth:

- ``brdf``: :func:`brdf.render.render` (numba, all cores, float64); its one-time compilation
  (or cache load) is reported apart. Like ``mi.render``, it estimates the image alone
  (``layers=False``); ``--layers`` times it with the variance, albedo and normal layers too;
- ``mitsuba``: ``mi.render`` with the ``llvm_ad_rgb`` variant (Dr.Jit's LLVM back end, SIMD
  float32 on all cores; it needs Debian's libllvm19, found as in ``mitsuba_baseline``), its
  ``path`` integrator and a box filter; the first render, which traces and compiles its
  kernels, is reported apart too.

Materials: ``lambert`` is ``diffuse``, ``ggx`` (no Fresnel) a ``roughconductor`` with
``material="none"``, a sum a ``blendbsdf`` of the lobes with their scales divided by the weight
(exact, as in :func:`brdf.export`). The Cornell box is Mitsuba's own ``cornell_box()``.

The scenes: ``cornell``; ``glossy`` (a GGX sphere, alpha 0.1, on a Lambertian floor under a
small area light); ``plastic`` (a ``lambert + ggx`` sphere there); ``furnace`` (a rough GGX
sphere alone in a constant environment); ``envmap`` (a ``lambert + ggx`` sphere filling the
view, lit only by an environment map); ``textured`` (a floor whose albedo is an image);
``mesh`` (a 40,000-triangle sphere); ``merl`` (a measured table on the MERL grid);
``point`` and ``spot`` (point and spot lights). ``--scene void`` (left out of ``--all``
unless named with it) moves the furnace's sphere behind its camera: every path ends at its
camera ray, in the constant environment, so a sample costs what a path costs without a
vertex; the furnace's time less the void's, over the furnace's vertices a sample, is what a
vertex costs (printed last with ``--stages``, which counts the vertices). Two have no
identical counterpart in Mitsuba, and their mean images are not compared: ``merl``
(Mitsuba's ``measured`` plugin reads an RGL tensor, here written from the model the table was
measured from, by :func:`brdf.export`'s ``measured=True``: another resampling of the same
BRDF) and ``spot``
(Mitsuba's spot light falls off smoothly from ``beam_width`` to ``cutoff_angle``, ours as
cos^n; it is given the same cone).

Prints per scene samples (paths) per second of each, the best of ``--repeats`` renders taken
in turns (ours, theirs, ours, ...), the ratio of the bests, the median and range of the
turn-by-turn ratios, and the relative difference of the mean images (goal: within 0.2 %):
of the first render's, and its mean and standard error over every turn (each renders a new
seed in both); then a table of all the scenes, ``*`` marking those that ours traces in
blocks of SIMD lanes (``render.traced_in_blocks``). With ``--stages``, one more render of ours
per scene times the path tracer's stages in its kernels (``render(..., stats=True)``,
x86-64), and a last table gives each stage's CPU nanoseconds per sample, scene by scene: the
stages of the packet of paths, which traces every scene when timed (the scenes marked ``*``
ran in blocks in the timed renders).
"""

import argparse
import math
import os
import statistics
import tempfile
import time

import numpy as np

from mitsuba_baseline import setup_llvm

#: camera looking at the sphere on the floor
_CAM = {"origin": (0.0, 1.2, 5.0), "target": (0.0, -0.2, 0.0), "up": (0.0, 1.0, 0.0),
        "fov": 40.0}
#: a Lambertian floor (y = -1, 8 x 8, facing up) and a small area light (0.5 x 0.5 at y = 3,
#: facing down)
_FLOOR = ("rectangle", {"to_world": ("rot_x", -90.0, 4.0, (0.0, -1.0, 0.0))},
          "lambert(albedo=0.5)")
_AREA = ("rectangle", {"to_world": ("rot_x", 90.0, 0.25, (0.0, 3.0, 0.0)),
                       "emission": (60.0, 60.0, 60.0)}, None)
_SPHERE = ("sphere", {"centre": (0.0, 0.0, 0.0), "radius": 1.0})
_PLASTIC = "lambert(albedo=0.4) + ggx(alpha=0.2, ks=0.5)"
#: the same in RGB, as the MERL grid's table holds it
_PLASTIC_RGB = "lambert(albedo=[0.4,0.4,0.4]) + ggx(alpha=0.2, ks=[0.5,0.5,0.5])"

#: name -> description: camera, shapes (kind, geometry, material spec), lights, environment,
#: and whether Mitsuba renders the same thing (else the mean images are not compared)
#: a rough GGX sphere alone in a constant environment, seen whole
_FURNACE = {"camera": {"origin": (0.0, 0.0, 4.0), "target": (0.0, 0.0, 0.0),
                       "up": (0.0, 1.0, 0.0), "fov": 32.0},
            "shapes": [_SPHERE + ("ggx(alpha=0.5)",)], "environment": "constant"}

SCENES = {
    "glossy": {"camera": _CAM, "shapes": [_SPHERE + ("ggx(alpha=0.1)",), _FLOOR, _AREA]},
    "plastic": {"camera": _CAM, "shapes": [_SPHERE + (_PLASTIC,), _FLOOR, _AREA]},
    "furnace": _FURNACE,
    # the furnace with its sphere behind the camera: every camera ray escapes, so a sample
    # costs what a path costs without a vertex (a diagnostic, not in --all; see the docstring)
    "void": {**_FURNACE, "shapes": [("sphere", {"centre": (0.0, 0.0, 8.0), "radius": 1.0},
                                     _FURNACE["shapes"][0][2])]},
    "envmap": {"camera": {"origin": (0.0, 0.0, 2.2), "target": (0.0, 0.0, 0.0),
                          "up": (0.0, 1.0, 0.0), "fov": 40.0},
               "shapes": [_SPHERE + (_PLASTIC,)], "environment": "map"},
    "textured": {"camera": _CAM, "shapes": [_SPHERE + ("lambert(albedo=0.6)",),
                                            _FLOOR[:2] + ("lambert", "texture"), _AREA]},
    "mesh": {"camera": _CAM, "shapes": [("mesh", {}, _PLASTIC), _FLOOR, _AREA]},
    "merl": {"camera": _CAM, "shapes": [_SPHERE + ("merl:" + _PLASTIC_RGB,), _FLOOR, _AREA],
             "same": False},
    "point": {"camera": _CAM, "shapes": [_SPHERE + (_PLASTIC,), _FLOOR],
              "lights": [("point", {"position": (1.0, 3.0, 1.0), "intensity": 20.0})]},
    "spot": {"camera": _CAM, "shapes": [_SPHERE + (_PLASTIC,), _FLOOR],
             "lights": [("spot", {"position": (1.0, 3.0, 1.0), "direction": (-1.0, -3.0, -1.0),
                                  "intensity": 20.0, "cutoff": 30.0})], "same": False},
}
#: scenes that diagnose rather than stand for a workload: timed only when named
DIAGNOSTIC = ("void",)
ALL = ("cornell",) + tuple(n for n in SCENES if n not in DIAGNOSTIC)


def _matrix(desc):
    """4 x 4 matrix of ("rot_x", degrees, uniform scale, translation): T . R . S."""
    _, deg, scale, t = desc
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    m = np.eye(4)
    m[:3, :3] = np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) * scale
    m[:3, 3] = t
    return m


def _texture():
    """An RGB albedo image (128 x 128) symmetric under u <-> 1 - u, v <-> 1 - v and u <-> v, so
    that the two renderers' texture coordinate conventions cannot change the image; smooth, so
    that their filters barely do."""
    x = np.abs(np.linspace(-1.0, 1.0, 128))
    r = np.maximum(x[:, None], x[None, :])
    band = 0.5 + 0.5 * np.cos(6.0 * math.pi * r)
    return np.stack([0.2 + 0.6 * band, 0.3 + 0.3 * band, 0.7 - 0.5 * band], -1).astype(np.float32)


def _environment_map():
    """An equirectangular sky (64 x 128): a gradient from a dim ground to a blue zenith, and
    a bright warm patch (a low sun)."""
    h, w = 64, 128
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(w) + 0.5) / w
    up = np.cos(math.pi * v)[:, None] * np.ones((1, w))
    sky = np.stack([0.3 + 0.2 * up, 0.4 + 0.3 * up, 0.5 + 0.5 * up], -1)
    sun = np.exp(-(((v[:, None] - 0.35) / 0.05) ** 2 + ((u[None, :] - 0.3) / 0.04) ** 2))
    sky = sky + 20.0 * sun[..., None] * np.array([1.0, 0.9, 0.7])
    return np.maximum(sky, 0.0).astype(np.float32)


def _uv_sphere(n_theta=101, n_phi=202):
    """A unit sphere of 2 n_phi (n_theta - 1) triangles (>= 40,000), with vertex normals."""
    th = np.linspace(0.0, math.pi, n_theta + 1)
    ph = np.linspace(0.0, 2.0 * math.pi, n_phi + 1)[:-1]
    rings = [np.array([[0.0, 1.0, 0.0]])]
    for t in th[1:-1]:
        rings.append(np.stack([np.sin(t) * np.cos(ph), np.full(n_phi, np.cos(t)),
                               -np.sin(t) * np.sin(ph)], -1))
    rings.append(np.array([[0.0, -1.0, 0.0]]))
    v = np.concatenate(rings)
    faces = []
    start = 1
    for j in range(n_phi):                                       # the top cap
        faces.append((0, start + j, start + (j + 1) % n_phi))
    for i in range(n_theta - 2):                                 # the bands
        a, b = start + i * n_phi, start + (i + 1) * n_phi
        for j in range(n_phi):
            k = (j + 1) % n_phi
            faces.append((a + j, b + j, b + k))
            faces.append((a + j, b + k, a + k))
    last, bottom = start + (n_theta - 2) * n_phi, len(v) - 1
    for j in range(n_phi):                                       # the bottom cap
        faces.append((last + j, bottom, last + (j + 1) % n_phi))
    return v, np.array(faces, np.int64)


def _write_ply(path, v, n, f):
    """A binary little-endian PLY of vertices ``v``, normals ``n`` and triangles ``f``."""
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n"
            + "".join(f"property float {c}\n" for c in ("x", "y", "z", "nx", "ny", "nz"))
            + f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    faces = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", 3)])
    faces["n"], faces["i"] = 3, f
    with open(path, "wb") as out:
        out.write(head.encode("ascii"))
        out.write(np.hstack([v, n]).astype("<f4").tobytes())
        out.write(faces.tobytes())


# --- our scene --------------------------------------------------------------------------------

def _material_ours(spec):
    import brdf
    if spec.startswith("merl:"):
        return brdf.measure(brdf.parse(spec[5:]), "merl")
    return brdf.parse(spec)


def build_ours(desc, depot):
    from brdf import render
    cam = render.Camera(**desc["camera"])
    shapes = []
    for kind, geo, spec, *rest in desc["shapes"]:
        if kind == "sphere":
            shapes.append(render.Sphere(geo["centre"], geo["radius"], _material_ours(spec)))
        elif kind == "rectangle":
            mat = None if spec is None else _material_ours(spec)
            if rest:
                mat = render.Material(mat, {"lambert.albedo": _texture()})
            shapes.append(render.rectangle(_matrix(geo["to_world"]), mat,
                                           emission=geo.get("emission")))
        elif kind == "mesh":
            v, f = depot["mesh"]
            shapes.append(render.Mesh(v, f, _material_ours(spec), normals=v))
    lights = []
    for kind, x in desc.get("lights", ()):
        if kind == "point":
            lights.append(render.PointLight(x["position"], x["intensity"]))
        else:
            lights.append(render.SpotLight(x["position"], x["direction"], x["intensity"],
                                           cutoff=x["cutoff"]))
    env = desc.get("environment")
    if env == "constant":
        env = render.Environment(1.0)
    elif env == "map":
        env = render.Environment(1.0, _environment_map().astype(float))
    return render.Scene(cam, shapes, lights, env)


# --- Mitsuba's scene --------------------------------------------------------------------------

def _rgb(value):
    return {"type": "rgb", "value": [float(c) for c in np.broadcast_to(value, (3,))]}


def _bsdf_theirs(mi, spec, depot, texture=False):
    """Mitsuba's BSDF for a spec of lambert and ggx lobes (see the module docstring)."""
    import brdf
    if spec.startswith("merl:"):
        path = os.path.join(depot["dir"], "merl.xml")
        if not os.path.exists(path):
            brdf.export(brdf.parse(spec[5:]), "mitsuba", path, measured=True)
        return {"type": "measured", "filename": os.path.join(depot["dir"], "merl.bsdf")}
    model = brdf.parse(spec)
    lobes = list(model.lobes) if len(model.lobes) > 1 else [model]
    scales = []
    out = []
    for lobe in lobes:
        p = {k.split(".")[-1]: v for k, v in lobe.params.items()}
        if lobe.name == "lambert":
            scales.append(float(np.max(p["albedo"])))
            out.append(lambda w, p=p: {
                "type": "diffuse", "reflectance":
                {"type": "bitmap", "bitmap": mi.Bitmap(_texture() / w), "raw": True}
                if texture else _rgb(np.asarray(p["albedo"]) / w)})
        elif lobe.name == "ggx":
            scales.append(float(np.max(p["ks"])))
            out.append(lambda w, p=p: {
                "type": "roughconductor", "material": "none", "distribution": "ggx",
                "alpha": float(p["alpha"]), "specular_reflectance": _rgb(np.asarray(p["ks"]) / w)})
        else:
            raise ValueError(f"no Mitsuba BSDF for {lobe.name}")
    if len(out) == 1:
        return out[0](1.0)
    if len(out) != 2:
        raise ValueError("two lobes at most")
    # a blend is convex, (1 - w) f1 + w f2: each lobe's scale divided by its weight
    w = scales[1] / (scales[0] + scales[1])
    return {"type": "blendbsdf", "weight": w, "bsdf_0": out[0](1.0 - w), "bsdf_1": out[1](w)}


def build_theirs(mi, desc, depot, size, depth):
    cam = desc["camera"]
    scene = {"type": "scene", "integrator": {"type": "path", "max_depth": depth}, "sensor": {
        "type": "perspective", "fov": cam["fov"], "fov_axis": "x",
        "to_world": mi.ScalarTransform4f().look_at(origin=cam["origin"], target=cam["target"],
                                                   up=cam["up"]),
        "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}},
    }}
    for i, (kind, geo, spec, *rest) in enumerate(desc["shapes"]):
        if kind == "sphere":
            shape = {"type": "sphere", "center": list(geo["centre"]), "radius": geo["radius"]}
        elif kind == "rectangle":
            shape = {"type": "rectangle",
                     "to_world": mi.ScalarTransform4f(_matrix(geo["to_world"]).tolist())}
            if "emission" in geo:
                shape["emitter"] = {"type": "area", "radiance": _rgb(geo["emission"])}
        else:
            shape = {"type": "ply", "filename": depot["ply"]}
        shape["bsdf"] = ({"type": "diffuse", "reflectance": _rgb(0.0)} if spec is None
                         else _bsdf_theirs(mi, spec, depot, bool(rest)))
        scene[f"shape{i}"] = shape
    for i, (kind, x) in enumerate(desc.get("lights", ())):
        light = {"type": kind, "position": list(x["position"]), "intensity": _rgb(x["intensity"])}
        if kind == "spot":
            p = np.asarray(x["position"])
            light = {"type": "spot", "intensity": _rgb(x["intensity"]),
                     "cutoff_angle": x["cutoff"], "beam_width": 0.5 * x["cutoff"],
                     "to_world": mi.ScalarTransform4f().look_at(
                         origin=p.tolist(), target=(p + np.asarray(x["direction"])).tolist(),
                         up=[0.0, 0.0, 1.0])}
        scene[f"light{i}"] = light
    env = desc.get("environment")
    if env == "constant":
        scene["env"] = {"type": "constant", "radiance": _rgb(1.0)}
    elif env == "map":
        scene["env"] = {"type": "envmap", "bitmap": mi.Bitmap(_environment_map())}
    return mi.load_dict(scene)


# --- timing -----------------------------------------------------------------------------------

def _timed(fn, seed):
    t = time.perf_counter()
    out = fn(seed)
    return time.perf_counter() - t, out


def bench(name, args, mi, depot):
    """Time scene ``name`` in both renderers, in turns; the figures as a dict."""
    from brdf import render
    if name == "cornell":
        scene = render.builtin("cornell")
        d = mi.cornell_box()
        d["integrator"]["max_depth"] = args.depth
        d["sensor"]["film"]["width"] = d["sensor"]["film"]["height"] = args.size
        mscene, same = mi.load_dict(d), True
    else:
        desc = SCENES[name]
        scene = build_ours(desc, depot)
        mscene, same = build_theirs(mi, desc, depot, args.size, args.depth), desc.get("same",
                                                                                       True)
    compile_seconds = []

    means, mmeans = [], []

    def ours(seed):
        r = render.render(scene, spp=args.spp, size=args.size, seed=seed, max_depth=args.depth,
                          layers=args.layers, progress=False)
        compile_seconds.append(r.compile_seconds)
        means.append(r.image.mean(axis=(0, 1)))
        return r.image

    def theirs(seed):
        image = np.array(mi.render(mscene, spp=args.spp, seed=seed))
        mmeans.append(image[..., :3].mean(axis=(0, 1)))
        return image

    first, img = _timed(ours, 0)
    mfirst, mimg = _timed(theirs, 0)
    # the two take turns, so that the shared host's drift touches both alike
    times, mtimes = [], []
    for r in range(args.repeats):
        times.append(_timed(ours, r + 1)[0])
        mtimes.append(_timed(theirs, r + 1)[0])
    n = args.size * args.size * args.spp
    pairs = sorted(m / t for t, m in zip(times, mtimes))
    a, b = img.mean(axis=(0, 1)), mimg[..., :3].mean(axis=(0, 1))
    # every turn renders a new seed in both, so the turns' differences of the mean images
    # give the difference with its standard error: one render of a sharp highlight scatters
    # by a few tenths of a per cent, as much as the goal
    diffs = (np.array(means) - np.array(mmeans)) / np.maximum(np.array(mmeans), 1e-12)
    worst = int(np.argmax(np.abs(diffs.mean(axis=0))))
    fig = {"name": name, "blocks": render.traced_in_blocks(scene),
           "ours": n / min(times), "theirs": n / min(mtimes),
           "best": min(mtimes) / min(times), "median": statistics.median(pairs),
           "low": pairs[0], "high": pairs[-1], "same": same,
           "rel": float(diffs[:, worst].mean()),
           "se": float(diffs[:, worst].std(ddof=1) / np.sqrt(len(diffs)))}
    print(f"[{name}] brdf first call {first:6.2f} s (compile or cache load "
          f"{compile_seconds[0]:.2f} s), best {min(times):6.3f} s, {fig['ours'] / 1e6:6.2f} M "
          f"samples/s ({'with' if args.layers else 'without'} layers); mitsuba first call "
          f"{mfirst:6.2f} s, best {min(mtimes):6.3f} s, {fig['theirs'] / 1e6:6.2f} M samples/s")
    print(f"[{name}] ratio brdf / mitsuba {fig['best']:.2f}x best against best; turn by turn "
          f"median {fig['median']:.2f}x, {fig['low']:.2f}-{fig['high']:.2f}x")
    print(f"[{name}] mean image brdf {np.round(a, 5)} mitsuba {np.round(b, 5)} relative "
          f"difference {np.round(np.abs(a - b) / b * 100, 3)} % (seed 0); over "
          f"{len(diffs)} seeds {100 * fig['rel']:+.3f} +- {100 * fig['se']:.3f} % "
          "(mean +- standard error, the channel furthest off)"
          + ("  (goal < 0.2 %)" if same else "  (not the same material or light: not compared)"),
          flush=True)
    if args.stages:
        fig["stats"] = render.render(scene, spp=args.spp, size=args.size, seed=0,
                                     max_depth=args.depth, layers=args.layers, progress=False,
                                     stats=True).stats
        print(f"[{name}] stages of one more render (CPU seconds of all threads):")
        print("\n".join("    " + line for line in fig["stats"].table().splitlines()), flush=True)
    return fig


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--depth", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--layers", action="store_true",
                    help="ours also estimates the variance, albedo and normal layers")
    ap.add_argument("--scene", action="append", choices=ALL + DIAGNOSTIC,
                    help="a scene to time (repeatable; default: cornell)")
    ap.add_argument("--all", action="store_true", help="time every scene")
    ap.add_argument("--stages", action="store_true",
                    help="also time our stages (render(..., stats=True)) in one more render")
    args = ap.parse_args()
    # --all with --scene void: every scene, then the diagnostic named
    names = (ALL + tuple(n for n in args.scene or () if n not in ALL) if args.all
             else args.scene or ["cornell"])
    mi = setup_llvm()
    figures = []
    with tempfile.TemporaryDirectory() as tmp:
        depot = {"dir": tmp}
        if "mesh" in names:
            v, f = _uv_sphere()
            depot["mesh"], depot["ply"] = (v, f), os.path.join(tmp, "sphere.ply")
            _write_ply(depot["ply"], v, v, f)
        for name in names:
            figures.append(bench(name, args, mi, depot))
    print(f"\n{'scene':10s} {'brdf M/s':>9s} {'mitsuba M/s':>12s} {'best/best':>10s} "
          f"{'median':>7s} {'range':>11s} {'mean diff +- standard error':>28s}   "
          f"(*: traced in blocks)")
    for f in figures:
        diff = f"{100 * f['rel']:+.3f} +- {100 * f['se']:.3f} %" if f["same"] else "n/a"
        print(f"{f['name'] + ' *' * f['blocks']:10s} {f['ours'] / 1e6:9.2f} "
              f"{f['theirs'] / 1e6:12.2f} "
              f"{f['best']:9.2f}x {f['median']:6.2f}x {f['low']:5.2f}-{f['high']:4.2f}x "
              f"{diff:>28s}")
    if args.stages:
        n = args.size * args.size * args.spp
        stages = list(figures[0]["stats"].seconds)
        print(f"\nCPU ns per sample, stage by stage (all threads; mitsuba's wall ns per sample "
              f"times {os.cpu_count()} cores for scale)")
        print(f"{'scene':10s} " + " ".join(f"{s[:11]:>11s}" for s in stages)
              + f" {'all':>7s} {'mitsuba':>8s} {'shaded':>7s}")
        for f in figures:
            st = f["stats"]
            print(f"{f['name']:10s} " + " ".join(f"{1e9 * st.seconds[s] / n:11.1f}"
                                                 for s in stages)
                  + f" {1e9 * st.thread_seconds / n:7.1f} {1e9 * os.cpu_count() / f['theirs']:8.1f}"
                  + f" {st.shaded / n:7.3f}")
        print("(shaded: vertices shaded a sample; the stages are the packet's, which traces "
              "every scene when timed)")
        by_name = {f["name"]: f for f in figures}
        if "furnace" in by_name and "void" in by_name:
            # a sample of the furnace is the void's path plus its vertices (one at most a
            # path: the sphere is convex), counted in the stages' render
            furnace, void = by_name["furnace"], by_name["void"]
            hits = furnace["stats"].shaded / n
            ours = [os.cpu_count() * 1e9 / f["ours"] for f in (furnace, void)]
            theirs = [os.cpu_count() * 1e9 / f["theirs"] for f in (furnace, void)]
            print(f"\nCPU ns a sample, best renders: furnace ours {ours[0]:.1f}, mitsuba "
                  f"{theirs[0]:.1f}; void (no vertex) ours {ours[1]:.1f}, mitsuba "
                  f"{theirs[1]:.1f}; a furnace vertex ({hits:.3f} a sample) ours "
                  f"{(ours[0] - ours[1]) / hits:.1f}, mitsuba {(theirs[0] - theirs[1]) / hits:.1f}")


if __name__ == "__main__":
    main()
