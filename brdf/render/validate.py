"""Measured versus fitted: render a table and a model in the same scene and compare images."""

import json
from pathlib import Path

from ..errors import OutputError

__all__ = ["validate", "OUTPUTS"]

#: Files :func:`validate` writes into its folder (each name after the ``prefix``)
OUTPUTS = ("measured.exr", "fitted.exr", "measured.png", "fitted.png", "difference.png",
           "flip.png", "comparison.png", "metrics.json")


def validate(data, fitted, outdir, scene="sphere", spp=64, size=(256, 256), seed=0,
             force=False, prefix="", **options):
    """Render ``data`` (a measured table) and ``fitted`` (a model, spec or fit report) in the
    same scene with the same seed, and write into ``outdir``: both images (EXR and PNG
    previews), a false-colour difference (red: the fit is brighter), the FLIP error map,
    ``comparison.png`` (measured | fitted | difference | FLIP in one figure, each with its
    colour bar: :func:`brdf.viz.plots.validation_figure`) and ``metrics.json`` (RMSE, relative
    MSE, mean FLIP; fitted against measured). Every file name starts with ``prefix`` (the demo
    writes several materials into one folder).

    ``scene`` names a built-in scene or a scene file whose shapes use ``"@material"``.
    Returns the metrics dictionary.
    """
    from . import builtin, load, render
    from .image import false_colour, flip_error, magma, metrics, tonemap, write_png
    from .scene import Material
    from ..formatting import round_numbers, significant
    from ..viz.plots import save_figure, validation_figure
    out = Path(outdir)
    if out.exists() and not out.is_dir():
        raise OutputError(f"{out}: exists and is not a folder")
    if not force:
        for name in OUTPUTS:
            if (out / f"{prefix}{name}").exists():
                raise OutputError(f"{out / f'{prefix}{name}'}: exists; pass --force "
                                  "(force=True) to replace it")
    out.mkdir(parents=True, exist_ok=True)
    fitted_model = Material(fitted).resolve()
    images = {}
    for name, material in (("measured", data), ("fitted", fitted_model)):
        s = load(scene, material) if str(scene).lower().endswith((".json", ".toml")) else \
            builtin(scene, material)
        images[name] = render(s, spp=spp, size=size, seed=seed, **options)
        images[name].save(out / f"{prefix}{name}.exr", force=True)
        write_png(out / f"{prefix}{name}.png", tonemap(images[name].image), force=True)
    test, ref = images["fitted"].image, images["measured"].image
    result, _ = metrics(test, ref, flip=False)
    result["flip"], error = flip_error(test, ref)
    write_png(out / f"{prefix}difference.png", false_colour(test - ref), force=True)
    write_png(out / f"{prefix}flip.png", magma(error), force=True)
    result.update({"scene": str(scene), "spp": int(spp), "seed": int(images["fitted"].seed),
                   "size": list(ref.shape[1::-1]), "model": str(fitted_model),
                   "seconds": {k: v.seconds for k, v in images.items()}})
    title = (f"{data} against {round_numbers(fitted_model)}; scene {Path(str(scene)).name}, "
             f"{ref.shape[1]} x {ref.shape[0]} px, {int(spp)} spp, seed {result['seed']}; "
             f"RMSE {significant(result['rmse'])}, relative MSE {significant(result['relmse'])}, "
             f"mean FLIP {significant(result['flip'])}")
    save_figure(validation_figure(ref, test, flip=error, title=title),
                out / f"{prefix}comparison.png", force=True)
    from ..io import atomic_output
    with atomic_output(out / f"{prefix}metrics.json", force=True) as tmp:
        tmp.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    return result
