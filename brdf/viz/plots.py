"""The 2-D plots BRDF analysts expect, with matplotlib: in-plane polar lobes of measurements
against a fit, the theta_h / theta_d image slice in the MERL layout, directional albedo against
theta_i, residual maps of a fit over a table's samples, the posterior's corner plot and
predictive bands (drawn from :class:`brdf.fitting.mcmc.Posterior`), and the validation renders
of a table and its fit in one figure (measured | fitted | difference | FLIP).

Each function returns a :class:`matplotlib.figure.Figure` built without pyplot, so no window
system or backend choice is involved (PNGs are drawn by Agg); :func:`save_figure` writes one
atomically.
"""

import math
import textwrap

import numpy as np

from ..errors import InputError
from ..geometry import directions_from_half_diff, half_diff_from_directions
from .samples import (channel_count, channel_label, channel_values, in_plane,
                      in_plane_directions, incidence, is_table, label, samples_near)

__all__ = ["inplane_plot", "slice_plot", "albedo_plot", "residual_plot", "corner_plot",
           "predictive_plot", "validation_figure", "save_figure", "F_LABEL"]

F_LABEL = "f_r [1/sr]"
#: Decades below the peak that a log-scale polar plot shows.
POLAR_DECADES = 3.0
#: Grazing cutoff of residual maps (degrees), as brdf.fit's default: the values past it are
#: the least reliable measurements and fits leave them out.
CUTOFF_DEG = 80.0
#: Most points in the measured-against-model scatter (the map bins every sample).
SCATTER_POINTS = 20000
#: Line colours of successive incidence angles or subjects (matplotlib's tab10).
CYCLE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
         "#7f7f7f", "#bcbd22", "#17becf")
#: Grey of pixels and bins without a value (below the horizon, no sample).
GAP_GREY = "#dddddd"
#: Decades under the peak that a slice's log colours span; lower values take the darkest colour.
SLICE_DECADES = 4.0
#: Narrowest panel of :func:`validation_figure`, in pixels at the figure's dpi.
MIN_PANEL_PIXELS = 256
#: Colours of named channels.
CHANNEL_COLOURS = {"r": "#d62728", "g": "#2ca02c", "b": "#1f77b4"}


def _grey_gaps(name):
    """Colour map ``name`` drawing missing pixels (NaN: below the horizon, no sample) grey."""
    from matplotlib import colormaps
    return colormaps[name].with_extremes(bad=GAP_GREY)


def _key(fig, entries):
    """A legend under the figure of what its masked and clipped regions mean: ``entries`` are
    ``(colours, text)`` pairs, a list of colours drawn as patches side by side."""
    from matplotlib.legend_handler import HandlerTuple
    from matplotlib.patches import Patch
    handles = [tuple(Patch(facecolor=c, edgecolor="#999999") for c in colours)
               for colours, _ in entries]
    fig.legend(handles, [text for _, text in entries], loc="outside lower center", fontsize=7,
               frameon=False, handler_map={tuple: HandlerTuple(ndivide=None)})


def save_figure(fig, path, force=False, dpi=100):
    """Write ``fig`` as PNG at ``path`` atomically; an existing file only with ``force``."""
    from ..io import atomic_output
    if not str(path).lower().endswith(".png"):
        raise InputError(f"{path}: plots are written as PNG; name the file ....png")
    with atomic_output(path, force) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    return path


def _figure(width, height, **options):
    from matplotlib.figure import Figure
    return Figure(figsize=(width, height), layout="constrained", **options)


def _check_channel(subject, channel):
    if channel is not None:
        channel_values(np.zeros(channel_count(subject)), channel)


def _title(subject, channel, extra="", width=70):
    """Subject, channel choice and ``extra``, wrapped: specs can be long."""
    which = channel_label(subject, channel)
    return textwrap.fill(", ".join(p for p in (label(subject), which, extra) if p), width)


# -- in-plane polar plot ----------------------------------------------------------------------

def _in_plane_samples(data, wi):
    """The samples near incidence ``wi`` and in its plane (:func:`samples_near`)."""
    return samples_near(data, wi, plane=True)


def _polar_floor(peak):
    """The round value at least :data:`POLAR_DECADES` below ``peak`` that a log-radius polar
    plot puts at its centre (lower values are drawn there too)."""
    return 10.0 ** math.floor(math.log10(peak) - POLAR_DECADES)


def _log_radius(ax, peak):
    """Map values to radii in decades above :func:`_polar_floor`; ticks read in 1/sr."""
    from matplotlib.ticker import FixedLocator, FuncFormatter
    floor = _polar_floor(peak)
    top = math.ceil(math.log10(peak / floor) - 1e-9)
    ax.set_rlim(0.0, top)
    ax.yaxis.set_major_locator(FixedLocator(np.arange(1, top + 1)))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda r, _: f"{floor * 10.0 ** r:g}"))
    return lambda f: np.log10(np.maximum(f, floor) / floor)


def inplane_plot(subject, theta_i=(0.0, 30.0, 60.0), phi_i=0.0, *, data=None, log=True,
                 cosine=False, channel=None, step=0.5):
    """In-plane polar plot: the BRDF in the plane of incidence for several incidence angles,
    measured samples as markers over the subject's curves.

    The polar angle is theta_o from the normal (up), negative on the incident side (left) and
    positive on the specular side (right); a dotted ray marks each incidence direction.

    Parameters
    ----------
    subject : Model or Table
        The curves (a table: its interpolation).
    theta_i : sequence of float
        Incidence angles, degrees in [0, 90).
    phi_i : float
        Azimuth of the plane of incidence, degrees.
    data : Table, optional
        Measured samples drawn as markers (default: ``subject`` when it is a table): those
        within 0.25, 1 or 2.5 degrees (the tightest that finds 30) of the incidence and of the
        plane (:func:`brdf.viz.samples.samples_near`).
    log : bool
        Log radius over :data:`POLAR_DECADES` decades.
    cosine : bool
        Plot f cos(theta_o) instead of f.
    channel : int, optional
        Default: the mean over channels.
    """
    _check_channel(subject, channel)
    if data is None and is_table(subject):
        data = subject
    angles = np.arange(-89.0, 89.0 + step / 2, step)
    rows = []
    for t in np.atleast_1d(theta_i):
        wi = incidence(t, phi_i)
        wo = in_plane_directions(wi, angles)
        curve = channel_values(subject.eval(np.broadcast_to(wi, wo.shape), wo), channel)
        points = None
        if data is not None:
            swo, values = _in_plane_samples(data, wi)
            points = (in_plane(wi, swo)[1], channel_values(values, channel)
                      * (swo[:, 2] if cosine else 1.0))
        rows.append((float(t), curve * (wo[:, 2] if cosine else 1.0), points))
    peak = max([np.nanmax(c) for _, c, _ in rows] +
               [np.nanmax(p[1]) for _, _, p in rows if p is not None and len(p[1])])
    if not peak > 0:
        raise InputError(f"{subject}: the BRDF is zero in the plane of incidence")
    fig = _figure(7.0, 3.6)
    ax = fig.add_subplot(projection="polar")
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)
    ax.set_thetamin(-90)
    ax.set_thetamax(90)
    radius = _log_radius(ax, peak) if log else (lambda f: f)
    floor = _polar_floor(peak)
    for k, (t, curve, points) in enumerate(rows):
        colour = CYCLE[k % len(CYCLE)]
        ax.plot(np.radians(angles), radius(curve), color=colour, lw=1.6,
                label=f"theta_i = {t:g}°")
        ax.plot([-math.radians(t)] * 2, [0, ax.get_rmax()], ls=":", color=colour, lw=1)
        if points is not None and len(points[0]):
            ax.plot(np.radians(points[0]), radius(points[1]), "o", ms=3.5, color=colour,
                    mfc="none", mew=0.9)
    if any(p is not None and len(p[0]) for _, _, p in rows):
        ax.plot([], [], "o", color="black", mfc="none", label="measured")
    lowest = min([np.nanmin(c) for _, c, _ in rows]
                 + [np.nanmin(p[1]) for _, _, p in rows if p is not None and len(p[1])])
    if log and lowest < floor:
        # a log radius has no room for them: they are drawn at the centre, and the legend
        # says so
        ax.plot([], [], " ", label=f"under {floor:g} 1/sr:\ndrawn at the centre")
    quantity = "f_r cos(theta_o) [1/sr]" if cosine else F_LABEL
    ax.set_title(_title(subject, channel, f"phi_i = {float(phi_i):g}°"), fontsize=9)
    # the half disc leaves the lower half of the axes empty: pull the label up into it
    ax.set_xlabel("radius: " + quantity + (" (log)" if log else "") + "\nangle: theta_o "
                  "[deg], incident side < 0 < specular side", fontsize=9, labelpad=-30)
    ax.set_rlabel_position(-90)
    ax.tick_params(axis="y", labelsize=7)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, frameon=False)
    return fig


# -- theta_h / theta_d slice (MERL layout) ----------------------------------------------------

def _merl_theta_h_axis(ax):
    """x from sqrt(theta_h / 90 deg): the MERL table's theta_h spacing, ticks in degrees."""
    ticks = np.array([0, 1, 5, 10, 20, 30, 45, 60, 90])
    ax.set_xticks(np.sqrt(ticks / 90.0), [f"{t:g}" for t in ticks])
    ax.set_xlabel("theta_h [deg] (square-root spacing, as MERL)")


def slice_plot(subject, phi_d=90.0, *, channel=None, resolution=90):
    """The theta_h / theta_d image at a fixed phi_d in the MERL layout, log colour.

    Specular reflection is the left column (theta_h = 0), retro-reflection the bottom row
    (theta_d = 0), grazing Fresnel rises at the top; pixels whose directions fall below the
    horizon, or whose value is not positive (a log scale has no place for it), are left grey
    (Burley 2012, "Physically-based shading at Disney", fig. 5). The colours span at most
    :data:`SLICE_DECADES` decades under the peak; lower values are clipped to the darkest. A
    legend under the image says which of these the picture holds, and that the darkest colour
    is the lowest value, not a gap.
    """
    from matplotlib.colors import LogNorm
    _check_channel(subject, channel)
    if not math.isfinite(phi_d):
        raise InputError(f"phi_d {phi_d!r} must be a finite number of degrees")
    u = (np.arange(resolution) + 0.5) / resolution
    theta_h = 0.5 * math.pi * u ** 2                     # MERL: theta_h = (pi/2) u^2
    theta_d = 0.5 * math.pi * (np.arange(resolution) + 0.5) / resolution
    wi, wo = directions_from_half_diff(theta_h[None, :], 0.0, theta_d[:, None],
                                       math.radians(phi_d))
    f = channel_values(subject.eval(wi, wo), channel)
    below = (wi[..., 2] <= 0) | (wo[..., 2] <= 0)
    not_positive = ~below & ~(f > 0)
    f = np.where(below | not_positive, np.nan, f)
    if not np.isfinite(f).any():
        raise InputError(f"{subject}: no positive value on the slice phi_d = {phi_d:g}")
    peak = float(np.nanmax(f))
    floor = max(float(np.nanmin(f)), peak * 10.0 ** -SLICE_DECADES)
    clipped = bool(np.nanmin(f) < floor)
    cmap = _grey_gaps("magma")
    fig = _figure(5.6, 5.0)
    ax = fig.add_subplot()
    image = ax.imshow(f, origin="lower", extent=(0, 1, 0, 90), aspect="auto", cmap=cmap,
                      norm=LogNorm(vmin=floor, vmax=peak), interpolation="nearest")
    _merl_theta_h_axis(ax)
    ax.set_ylabel("theta_d [deg]")
    ax.set_title(_title(subject, channel, f"phi_d = {phi_d:g}°", width=60), fontsize=9)
    fig.colorbar(image, ax=ax, label=F_LABEL + " (log)", extend="min" if clipped else "neither")
    keys = [([cmap(0.0)], f"darkest: {floor:.3g} 1/sr" + (
        f" and below ({SLICE_DECADES:g} decades under the peak; lower values clipped)"
        if clipped else ", the lowest value (not missing data)"))]
    if below.any():
        keys.append(([GAP_GREY], "grey: no value, a direction below the horizon"))
    if not_positive.any():
        keys.append(([GAP_GREY], "grey: f_r <= 0, which a log scale cannot show"))
    _key(fig, keys)
    return fig


# -- directional albedo -----------------------------------------------------------------------

def albedo_plot(*subjects, channel=None, steps=90, phi_i=0.0):
    """Directional albedo a(theta_i) of one or more subjects with the energy limit 1.

    Per subject, the mean over channels as a line with the range of the channels shaded (the
    energy check concerns the largest), or one ``channel``. Models use ``model.albedo``
    (adaptive cubature), tables their quadrature over the interpolant, as ``brdf.check`` does.
    """
    if not subjects:
        raise InputError("give at least one model or table")
    theta = np.linspace(0.0, 89.0, int(steps))
    wi = np.stack([incidence(t, phi_i) for t in theta])
    fig = _figure(6.4, 4.4 + 0.3 * len(subjects))
    ax = fig.add_subplot()
    top = 1.0
    for k, subject in enumerate(subjects):
        _check_channel(subject, channel)
        if is_table(subject) and getattr(subject, "in_plane", False):
            raise InputError(f"{subject}: an in-plane scan has no directional albedo (nothing "
                             "was measured out of the plane)")
        a = np.asarray(subject.albedo(wi), float)
        colour = CYCLE[k % len(CYCLE)]
        label = _title(subject, channel, width=90)
        if channel is None and a.shape[-1] > 1:
            ax.fill_between(theta, a.min(axis=-1), a.max(axis=-1), color=colour, alpha=0.2,
                            lw=0, label="range of the channels")
        line = channel_values(a, channel)
        ax.plot(theta, line, color=colour, lw=1.6, label=label)
        top = max(top, float(np.nanmax(a)))
    ax.axhline(1.0, color="black", ls="--", lw=1, label="1: energy conservation limit")
    ax.set_xlim(0, 90)
    ax.set_ylim(0, 1.08 * top)
    ax.set_xlabel("theta_i [deg]")
    ax.set_ylabel("directional albedo a(theta_i)")
    fig.legend(fontsize=7, loc="outside lower center")
    ax.grid(alpha=0.3)
    return fig


# -- residual maps ----------------------------------------------------------------------------

def _fit_samples(model, table, channel, cutoff):
    """Measured and model values over the table's samples within the cutoff, both positive."""
    if not is_table(table):
        raise InputError(f"{table}: residuals need a measured table (brdf.read)")
    _check_channel(table, channel)
    wi, wo = np.asarray(table.wi, float), np.asarray(table.wo, float)
    measured = channel_values(table.values, channel)
    cos_cut = math.cos(math.radians(cutoff)) - 1e-12
    keep = (wi[:, 2] >= cos_cut) & (wo[:, 2] >= cos_cut) & np.isfinite(measured) \
        & (measured > 0)
    predicted = channel_values(model.eval(wi[keep], wo[keep]), channel)
    positive = predicted > 0
    if not positive.any():
        raise InputError(f"{table}: no sample within {cutoff:g} degrees where both the "
                         "measurement and the model are positive")
    return wi[keep][positive], wo[keep][positive], measured[keep][positive], \
        predicted[positive]


def residual_plot(model, table, *, channel=None, cutoff=CUTOFF_DEG, bins=None):
    """How a model misses a table: model against measured values (log-log, with the 1:1 line)
    and a map of the mean log10(model / measured) over (theta_h, theta_d), every sample within
    ``cutoff`` degrees binned, in the MERL layout of :func:`slice_plot`. ``bins`` per axis
    default to about two samples per bin on average, between 12 and 45."""
    wi, wo, measured, predicted = _fit_samples(model, table, channel, cutoff)
    log_ratio = np.log10(predicted / measured)
    theta_h, _, theta_d, _ = half_diff_from_directions(wi, wo)
    if bins is None:
        bins = int(np.clip(np.sqrt(len(measured) / 2), 12, 45))
    x = np.sqrt(np.clip(theta_h / (0.5 * math.pi), 0, 1))
    y = np.degrees(theta_d)
    edges = (np.linspace(0, 1, bins + 1), np.linspace(0, 90, bins + 1))
    total, _, _ = np.histogram2d(x, y, edges, weights=log_ratio)
    count, _, _ = np.histogram2d(x, y, edges)
    mean = np.where(count > 0, total / np.maximum(count, 1), np.nan).T
    limit = max(float(np.nanpercentile(np.abs(mean), 99)), 1e-3)
    clipped = int(np.sum(np.abs(mean) > limit))
    fig = _figure(11.0, 5.0)
    left, right = fig.subplots(1, 2)
    pick = np.unique(np.linspace(0, len(measured) - 1, min(len(measured), SCATTER_POINTS))
                     .round().astype(int))
    left.scatter(measured[pick], predicted[pick], s=3, alpha=0.4, lw=0, color=CYCLE[0])
    lo = min(measured.min(), predicted.min())
    hi = max(measured.max(), predicted.max())
    left.plot([lo, hi], [lo, hi], color="black", lw=1, label="model = measured")
    left.set(xscale="log", yscale="log", xlabel="measured " + F_LABEL,
             ylabel="model " + F_LABEL)
    rms = float(np.sqrt(np.mean(log_ratio ** 2)))
    left.set_title(f"{len(measured):,} samples within {cutoff:g}°; RMS log10 ratio "
                   f"{rms:.3f}", fontsize=9)
    left.legend(fontsize=8)
    left.grid(alpha=0.3)
    image = right.imshow(mean, origin="lower", extent=(0, 1, 0, 90), aspect="auto",
                         cmap=_grey_gaps("RdBu_r"), vmin=-limit, vmax=limit,
                         interpolation="nearest")
    _merl_theta_h_axis(right)
    right.set_ylabel("theta_d [deg]")
    right.set_title("mean over samples in each bin (blue: model too low)", fontsize=9)
    fig.colorbar(image, ax=right, label="log10(model / measured)",
                 extend="both" if clipped else "neither")
    keys = [([GAP_GREY], f"grey: no sample in the bin (beyond the {cutoff:g}° cutoff, below the "
                       "horizon or not measured)")] if np.isnan(mean).any() else []
    if clipped:
        ends = image.get_cmap()
        keys.append(([ends(0.0), ends(1.0)], f"{clipped} of {int(np.sum(count > 0))} bins "
                     f"beyond ±{limit:.3g} (the 99th percentile): clipped to the bar's ends"))
    if keys:
        _key(fig, keys)
    fig.suptitle(_title(table, channel, f"fitted by {label(model)}", width=140), fontsize=9)
    return fig


# -- posterior --------------------------------------------------------------------------------

def corner_plot(posterior, path, force=False, dpi=100):
    """The posterior's corner plot as PNG at ``path``
    (:meth:`brdf.fitting.mcmc.Posterior.corner`)."""
    posterior.corner(path, force=force, dpi=dpi)
    return path


def _band_channels(bands, names, channel):
    count = bands.shape[-1]
    if channel is not None:
        channel_values(np.zeros(count), channel)
        return [channel]
    if count > 3:
        raise InputError(f"the posterior has {count} channels; pick one to plot (channel=, "
                         "--channel)")
    return list(range(count))


def predictive_plot(posterior, data=None, *, theta_i=30.0, draws=100, seed=0, channel=None):
    """Posterior predictive bands (:meth:`~brdf.fitting.mcmc.Posterior.predictive`): the
    in-plane BRDF at ``theta_i`` with the measured in-plane samples, and the directional
    albedo with the limit 1; medians as lines, 68 % and 95 % bands shaded."""
    bands = posterior.predictive(theta_i=theta_i, draws=draws, seed=seed)
    slice_, curve = bands["in_plane"], bands["albedo"]
    model = posterior.fit.model
    names = getattr(data, "channel_names", None) or [str(c) for c in
                                                     range(slice_["bands"].shape[-1])]
    channels = _band_channels(slice_["bands"], names, channel)
    fig = _figure(11.0, 4.4)
    left, right = fig.subplots(1, 2)
    for ax, x, b in ((left, slice_["theta_o_deg"], slice_["bands"]),
                     (right, curve["theta_i_deg"], curve["bands"])):
        for c in channels:
            colour = CHANNEL_COLOURS.get(names[c], CYCLE[c % len(CYCLE)])
            ax.fill_between(x, b[0, :, c], b[4, :, c], color=colour, alpha=0.15, lw=0)
            ax.fill_between(x, b[1, :, c], b[3, :, c], color=colour, alpha=0.3, lw=0)
            ax.plot(x, b[2, :, c], color=colour, lw=1.4,
                    label=f"median, channel {names[c]}" if len(channels) > 1 else "median")
    left.fill_between([], [], [], color="grey", alpha=0.3, label="68 % band")
    left.fill_between([], [], [], color="grey", alpha=0.15, label="95 % band")
    if data is not None:
        wi = incidence(theta_i)
        wo, values = _in_plane_samples(data, wi)
        signed = in_plane(wi, wo)[1]
        for c in channels:
            colour = CHANNEL_COLOURS.get(names[c], CYCLE[c % len(CYCLE)])
            left.plot(signed, values[:, c], "o", ms=3, mfc="none", color=colour)
        left.plot([], [], "o", mfc="none", color="black", label="measured")
    left.set(yscale="log", xlim=(-90, 90), xlabel="theta_o [deg] (incident side < 0 < "
             "specular side)", ylabel=F_LABEL,
             title=f"in-plane, theta_i = {theta_i:g}°, {draws} posterior draws")
    right.axhline(1.0, color="black", ls="--", lw=1, label="1: energy conservation limit")
    right.set(xlim=(0, 90), xlabel="theta_i [deg]", ylabel="directional albedo",
              title="directional albedo")
    for ax in (left, right):
        ax.title.set_fontsize(9)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    # the bands are per channel: no channel choice in the title
    fig.suptitle(textwrap.fill(f"{label(model)}, posterior predictive", 140), fontsize=9)
    return fig


# -- validation renders -----------------------------------------------------------------------

def _percent(fraction):
    """A share of pixels for a legend: ``0 %``, ``< 0.1 %``, ``2.4 %``."""
    if fraction == 0:
        return "0 %"
    return "< 0.1 %" if fraction < 0.001 else f"{100 * fraction:.2g} %"


def _radiance_bar(fig, ax, top, clipped):
    """The colour bar of a tone-mapped render: linear radiance 0 to ``top`` through the same
    sRGB encoding as :func:`brdf.render.image.tonemap`, grey; ``clipped`` is the share of
    pixels with a channel above ``top`` (drawn white)."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import ListedColormap, Normalize
    from ..render.image import tonemap
    ramp = tonemap(np.linspace(0.0, 1.0, 256)) / 255.0
    grey = ListedColormap(np.repeat(ramp[:, None], 3, axis=1))
    bar = fig.colorbar(ScalarMappable(Normalize(0.0, top), grey), ax=ax, location="bottom",
                       extend="max" if clipped else "neither", shrink=0.9)
    bar.set_label(f"radiance per channel (linear), sRGB display\nabove {top:.3g} clipped to "
                  f"white:\n{_percent(clipped)} of pixels", fontsize=8)
    return bar


def validation_figure(measured, fitted, *, flip=None, exposure=0.0, title=None, dpi=100):
    """Measured | fitted | difference | FLIP: the validation renders of a table and its fit
    (the same scene and seed, :func:`brdf.render.validate`) in one figure, each panel with its
    colour bar.

    The two renders share a tone mapping (:func:`brdf.render.image.tonemap` at ``exposure``;
    the bar says how many pixels it clips); the difference is the luminance of fitted minus
    measured in blue (fit darker) to red (fit brighter), clipped at
    :func:`brdf.render.image.difference_scale`; FLIP is the per-pixel HDR-FLIP error of the
    fit against the measurement, 0 to 1.

    Parameters
    ----------
    measured, fitted : ndarray (h, w, 3)
        Linear RGB radiance (``RenderResult.image``).
    flip : ndarray (h, w), optional
        The per-pixel FLIP error (default: :func:`brdf.render.image.flip_error`).
    exposure : float
        Stops, as :func:`~brdf.render.image.tonemap`.
    title : str, optional
        A title above the panels (the scene, its settings, the metrics).
    dpi : int
        The resolution the figure will be saved at: the panels are sized so that a render
        keeps about its own pixels.
    """
    from ..render.image import (DIFFERENCE_PERCENTILE, difference_scale, flip_error, luminance,
                                tonemap)
    measured = np.asarray(measured, float)
    fitted = np.asarray(fitted, float)
    if measured.shape != fitted.shape or measured.ndim != 3 or measured.shape[-1] != 3:
        raise InputError(f"expected two linear RGB images (h, w, 3) of one size, got shapes "
                         f"{measured.shape} and {fitted.shape}")
    if flip is None:
        flip = flip_error(fitted, measured)[1]
    height, width = measured.shape[:2]
    # each panel about the render's own size (at least MIN_PANEL_PIXELS wide, so that a small
    # render still leaves room for its bar's labels), plus the bars below and the titles
    panel = max(width, MIN_PANEL_PIXELS) / dpi
    size = np.round(np.array([4 * panel + 0.6, panel * height / width + 1.6
                              + (0.3 if title else 0.0)]) * dpi) / dpi  # whole pixels
    fig = _figure(*size)
    axes = fig.subplots(1, 4)
    top = 2.0 ** -float(exposure)
    for ax, image, name in ((axes[0], measured, "measured (the table rendered)"),
                            (axes[1], fitted, "fitted (the model rendered)")):
        ax.imshow(tonemap(image, exposure), interpolation="antialiased")
        ax.set_title(name, fontsize=9)
        _radiance_bar(fig, ax, top, float(np.mean(np.any(image > top, axis=-1))))
    diff = luminance(fitted - measured)
    scale = difference_scale(diff)
    clipped = float(np.mean(np.abs(diff) > scale))
    shown = axes[2].imshow(diff, cmap="bwr", vmin=-scale, vmax=scale,
                           interpolation="antialiased")
    axes[2].set_title("difference: fitted - measured\n(red: fit brighter, blue: darker)",
                      fontsize=9)
    bar = fig.colorbar(shown, ax=axes[2], location="bottom", shrink=0.9,
                       extend="both" if clipped else "neither")
    bar.set_label(f"luminance difference (linear)\nclipped at ±{scale:.3g} (the "
                  f"{DIFFERENCE_PERCENTILE:g}th percentile):\n{_percent(clipped)} of pixels "
                  "beyond", fontsize=8)
    error = np.asarray(flip, float).reshape(height, width)
    shown = axes[3].imshow(error, cmap="magma", vmin=0.0, vmax=1.0,
                           interpolation="antialiased")
    axes[3].set_title(f"FLIP error of the fit (mean {float(np.mean(error)):.4g})", fontsize=9)
    bar = fig.colorbar(shown, ax=axes[3], location="bottom", shrink=0.9)
    bar.set_label("HDR-FLIP per pixel\n0: no visible difference\n1: the largest", fontsize=8)
    for ax in axes:
        # a frame, no ticks: the white of a zero difference still has an edge
        ax.set_xticks([])
        ax.set_yticks([])
    if title:
        # at most about 7.5 pixels a character at 9 points
        fig.suptitle(textwrap.fill(title, int(fig.get_figwidth() * dpi / 7.5)), fontsize=9)
    return fig
