"""Reflection lobes in 3-D with pyvista: r(wo) = f(wi, wo) cos(theta_o) as a deformed hemisphere.

For each incident direction the outgoing hemisphere is drawn with every direction wo pushed out
to the radius r(wo) and coloured by the same value: the picture of where a BRDF sends light
(the "lobe" of BRDF Explorer, Burley 2012). Options draw f alone (``cosine=False``) or a log
radius. Measured samples near the incidence sit on the surface as points; arrows show the
incident direction, its mirror direction and the normal, over a disc standing for the surface.

Without a display (or with ``pyvista.OFF_SCREEN``) pictures are rendered off screen to PNG; a
Linux machine then needs EGL (Debian: ``apt-get install -y --no-install-recommends libegl1
libgl1-mesa-dri``), which VTK's wheels load at run time.
"""

import ctypes.util
import math
import os
import sys
import textwrap

import numpy as np

from .. import arguments
from ..errors import BRDFError, InputError, OutputError
from ..geometry import reflect, spherical_to_cartesian
from .samples import (channel_count, channel_label, channel_values, incidence, is_table,
                      label, samples_near)

__all__ = ["lobe_surface", "lobe_plotter", "plot_lobes", "has_display", "LOG_DECADES",
           "HEADLESS_PACKAGES"]

#: A log-scale lobe spans this many decades below its peak (values under that sit at the origin).
LOG_DECADES = 3.0
#: Debian packages that give VTK an off-screen OpenGL context (EGL with Mesa's software driver).
HEADLESS_PACKAGES = ("libegl1", "libgl1-mesa-dri")
#: Largest ``resolution`` of a lobe: 2 n^2 outgoing directions per incidence.
MAX_RESOLUTION = 4096
#: Peak bytes per outgoing direction of a drawn lobe, counted once per incidence and once more
#: for the plotter's shared state. Measured 2026-12-03 (``lambert + ggx``, resolution 512,
#: 526,338 directions): 695, 809 and 952 MB for 1, 2 and 3 incidences, 474 MB at resolution
#: 64; the constant rounds those increments (about 250 B per direction per incidence) up.
LOBE_BYTES = 300
#: Colours: incident direction, mirror direction, normal, measured samples, surface patch.
COLOURS = {"wi": "#e07b00", "mirror": "#2b6cb0", "normal": "black", "samples": "black",
           "patch": "#c8c8c8"}


class RenderingError(BRDFError):
    """Rendering cannot start here (no display and no off-screen OpenGL, or no output path)."""


def has_display():
    """True when an interactive window can open (a display, and pyvista.OFF_SCREEN unset)."""
    import pyvista
    if pyvista.OFF_SCREEN:
        return False
    if sys.platform.startswith("linux"):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def _prepare_off_screen():
    """Point VTK at EGL on a Linux machine without a display, or say which packages it needs
    (VTK would otherwise fail inside the renderer with a less helpful message)."""
    if not sys.platform.startswith("linux") or os.environ.get("DISPLAY"):
        return
    if ctypes.util.find_library("EGL"):
        # VTK tries X first and warns when there is none; EGL is what will work
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    elif not ctypes.util.find_library("OSMesa"):
        raise RenderingError("off-screen rendering needs EGL or OSMesa and neither is "
                             "installed; on Debian/Ubuntu: apt-get install -y "
                             f"--no-install-recommends {' '.join(HEADLESS_PACKAGES)}")


def _hemisphere(resolution):
    """Outgoing directions on a (phi, theta) grid, shape (2 resolution + 1, resolution + 1, 3):
    theta_o from the normal to just above the horizon, phi closed (first row repeated last) so
    the mesh has no seam."""
    theta = np.linspace(0.0, 0.5 * math.pi * (1 - 1e-6), resolution + 1)
    phi = np.linspace(0.0, 2.0 * math.pi, 2 * resolution + 1)
    return spherical_to_cartesian(theta[None, :], phi[:, None])


def lobe_values(subject, wi, wo, cosine=True, channel=None):
    """r(wo) in 1/sr: ``subject.eval(wi, wo)`` reduced to one channel, times cos(theta_o)."""
    # a patch of area A under irradiance E sends I(wo) = L_o A cos(theta_o) = f E A cos(theta_o)
    # towards wo (Nicodemus et al. 1977, NBS Monograph 160): f cos is I per incident flux E A
    f = channel_values(subject.eval(np.broadcast_to(wi, wo.shape), wo), channel)
    return f * wo[..., 2] if cosine else f


def _radius(values, peak, log):
    """Radius of the drawn surface, in units of the largest lobe: the value over the peak, or
    with ``log`` the decades above ``peak 10^-LOG_DECADES`` over LOG_DECADES."""
    values = np.maximum(np.nan_to_num(values, nan=0.0), 0.0)
    if not log:
        return values / peak
    floor = peak * 10.0 ** -LOG_DECADES
    return np.clip(np.log10(np.maximum(values, floor) / floor) / LOG_DECADES, 0.0, None)


def lobe_surface(subject, wi, *, cosine=True, log=False, channel=None, resolution=48,
                 peak=None):
    """The lobe of ``subject`` for incidence ``wi`` as a pyvista mesh.

    Parameters
    ----------
    subject : Model or Table
        Anything with ``eval(wi, wo) -> (..., C)`` in 1/sr.
    wi : array_like, shape (3,)
        Unit incident direction in the local frame (z the normal).
    cosine : bool
        Draw f cos(theta_o) (the radiant intensity reflected towards wo per unit incident
        flux) or f alone.
    log : bool
        Log radius over :data:`LOG_DECADES` decades below ``peak``.
    channel : int, optional
        The channel drawn; default the mean over channels.
    resolution : int
        Polar steps over the hemisphere (azimuth steps are twice as many).
    peak : float, optional
        The value drawn at radius 1 (default: this lobe's maximum); pass the largest of several
        lobes to draw them to one scale.

    Returns
    -------
    pyvista.PolyData
        Points at r(wo) wo (scaled by 1/peak), with point data ``"value"`` (r in 1/sr).
    """
    import pyvista
    wi = np.asarray(wi, dtype=float)
    resolution = _resolution(resolution, 1, "lobe_surface")
    wo = _hemisphere(resolution)
    values = lobe_values(subject, wi, wo, cosine, channel)
    if not np.isfinite(values).any():
        raise InputError(f"{subject}: no finite value over the hemisphere at this incidence")
    peak = float(np.nanmax(values)) if peak is None else float(peak)
    if not peak > 0.0:
        raise InputError(f"{subject}: the lobe is zero everywhere at this incidence "
                         "(nothing to draw)")
    points = wo * _radius(values, peak, log)[..., None]
    grid = pyvista.StructuredGrid(points[..., 0], points[..., 1], points[..., 2])
    grid.point_data["value"] = values.ravel(order="F")
    return grid.extract_surface(algorithm="dataset_surface")


def _resolution(resolution, incidences, what):
    """``resolution`` checked (an integer of polar steps) and the memory its lobes need."""
    from ..memory import require
    resolution = arguments.integer(resolution, f"{what}: resolution", 4, MAX_RESOLUTION)
    directions = (2 * resolution + 1) * (resolution + 1)
    require(directions * LOBE_BYTES * (incidences + 1),
            f"{incidences} lobe{'s' if incidences > 1 else ''} at resolution {resolution}")
    return resolution


def _units(cosine):
    return "f_r cos(theta_o) [1/sr]" if cosine else "f_r [1/sr]"


def _peak(subject, directions, cosine, channel, resolution):
    """Largest r over every incidence, so all lobes share one scale and one colour bar."""
    wo = _hemisphere(resolution)
    return max(float(np.nanmax(lobe_values(subject, wi, wo, cosine, channel)))
               for wi in directions)


def _arrow(plotter, direction, length, colour, label):
    import pyvista
    plotter.add_mesh(pyvista.Arrow(start=(0, 0, 0), direction=direction, scale=length,
                                   tip_length=0.12, tip_radius=0.03, shaft_radius=0.01),
                     color=colour)
    plotter.add_point_labels(np.asarray([direction]) * length * 1.04, [label], font_size=14,
                             text_color=colour, shape=None, show_points=False,
                             always_visible=True)


def _add_lobe(plotter, subject, data, wi, options, peak, title, scalar_bar):
    """One incidence: surface, samples, arrows, normal, patch and title in the active view."""
    import pyvista
    cosine, log, channel = options["cosine"], options["log"], options["channel"]
    surface = lobe_surface(subject, wi, cosine=cosine, log=log, channel=channel,
                           resolution=options["resolution"], peak=peak)
    clim = (peak * 10.0 ** -LOG_DECADES, peak) if log else (0.0, peak)
    # the bar's title would sit on its labels: the units go in a text of their own
    bar = {"title": "", "vertical": False, "label_font_size": 12, "fmt": "%.3g",
           "n_labels": 5, "position_x": 0.48, "position_y": 0.03, "height": 0.07,
           "width": 0.48, "color": "black"}
    plotter.add_mesh(surface, scalars="value", cmap="viridis", clim=clim, log_scale=log,
                     smooth_shading=True, show_scalar_bar=scalar_bar, scalar_bar_args=bar)
    if scalar_bar:
        plotter.add_text("colour and radius:\n" + _units(cosine)
                         + (", log scale" if log else ""), position="lower_left", font_size=9)
    plotter.add_mesh(pyvista.Disc(center=(0, 0, -1e-3), inner=0.0, outer=1.15,
                                  normal=(0, 0, 1), c_res=64), color=COLOURS["patch"],
                     opacity=0.6)
    if data is not None:
        wo, values = samples_near(data, wi)
        if len(wo):
            r = _radius(channel_values(values, channel) * (wo[:, 2] if cosine else 1.0),
                        peak, log)
            plotter.add_mesh(pyvista.PolyData(wo * r[:, None]), color=COLOURS["samples"],
                             point_size=3, render_points_as_spheres=True)
    _arrow(plotter, wi, 1.15, COLOURS["wi"], "wi")
    _arrow(plotter, reflect(wi), 1.15, COLOURS["mirror"], "mirror")
    _arrow(plotter, np.array([0.0, 0.0, 1.0]), 1.1, COLOURS["normal"], "n")
    plotter.add_text(title, font_size=11, position="upper_left")
    # seen from the side (-y), a little above the surface, the plane of incidence facing us
    phi = math.atan2(wi[1], wi[0]) if np.hypot(wi[0], wi[1]) > 1e-9 else 0.0
    side = np.array([math.sin(phi), -math.cos(phi), 0.0])
    plotter.camera_position = [tuple(4.2 * side + (0, 0, 1.8)), (0, 0, 0.35), (0, 0, 1)]


def _directions(theta_i, phi_i):
    theta_i = np.atleast_1d(np.asarray(theta_i, float))
    if theta_i.size == 0:
        raise InputError("give at least one incidence angle theta_i")
    return [incidence(t, phi_i) for t in theta_i], theta_i


def lobe_plotter(subject, theta_i=(30.0,), phi_i=0.0, *, data=None, cosine=True, log=False,
                 channel=None, resolution=48, window_size=None, off_screen=None):
    """A pyvista Plotter showing the lobes of ``subject``, one view per incidence angle.

    Parameters
    ----------
    subject : Model or Table
        The surface drawn (a fitted model, or a table through its interpolation).
    theta_i : float or sequence of float
        Incidence polar angles, degrees in [0, 90).
    phi_i : float
        Incidence azimuth, degrees.
    data : Table, optional
        Measured samples drawn as points on the surface (default: ``subject`` itself when it is
        a table).
    cosine, log, channel, resolution
        As for :func:`lobe_surface`. All views share one scale: the largest lobe.
    window_size : (int, int), optional
        Pixels (default 520 x 480 per view).
    off_screen : bool, optional
        Default: when there is no display.

    Returns
    -------
    pyvista.Plotter
    """
    import pyvista
    directions, angles = _directions(theta_i, phi_i)
    if data is None and is_table(subject):
        data = subject
    if channel is not None:
        channel_values(np.zeros(channel_count(subject)), channel)  # one-line error if absent
    off_screen = (not has_display()) if off_screen is None else bool(off_screen)
    if off_screen:
        _prepare_off_screen()
    resolution = _resolution(resolution, len(directions), "lobe_plotter")
    peak = _peak(subject, directions, cosine, channel, resolution)
    if not peak > 0.0:
        raise InputError(f"{subject}: the lobe is zero everywhere at these incidences")
    n = len(directions)
    size = window_size or (520 * n, 480)
    plotter = pyvista.Plotter(shape=(1, n), off_screen=off_screen, window_size=list(size),
                              border=False)
    plotter.set_background("white")
    options = {"cosine": cosine, "log": log, "channel": channel, "resolution": resolution}
    which = channel_label(subject, channel)
    for k, (wi, t) in enumerate(zip(directions, angles)):
        plotter.subplot(0, k)
        title = textwrap.fill(label(subject), 64) + \
            f"\ntheta_i = {t:g}°, phi_i = {float(phi_i):g}°" + (f", {which}" if which else "")
        _add_lobe(plotter, subject, data, wi, options, peak, title, scalar_bar=k == n - 1)
    plotter.link_views()
    return plotter


def plot_lobes(subject, theta_i=(30.0,), phi_i=0.0, *, path=None, force=False, **options):
    """Show the lobes in a window, or write them to the PNG ``path``.

    With ``path`` (or without a display) the picture is rendered off screen and written
    atomically; an existing file is replaced only with ``force``. Other options as for
    :func:`lobe_plotter`.

    Returns
    -------
    ndarray, shape (H, W, 3) or None
        The rendered image (uint8) when rendered off screen.
    """
    from ..io import atomic_output
    if path is None and not has_display():
        raise RenderingError("no display to open a window on; give an output path "
                             "(-o lobe.png) to render off screen")
    if path is not None and not str(path).lower().endswith(".png"):
        raise InputError(f"{path}: lobe pictures are PNG files; name it ....png")
    if path is not None and os.path.exists(path) and not force:
        raise OutputError(f"{path}: exists; pass --force (force=True) to replace it")
    plotter = lobe_plotter(subject, theta_i, phi_i, off_screen=path is not None, **options)
    try:
        if path is None:
            plotter.show()
            return None
        with atomic_output(path, force) as tmp:
            return plotter.screenshot(str(tmp), return_img=True)
    finally:
        plotter.close()
