"""A study's figures as gait reports show them (``casflex study``): one row per joint, its angle and its moment
over the gait cycle (0-100 %), left and right overlaid (left red, right green, as gait labs draw them), each
side's mean and its band of +- 1 standard deviation, each side's mean toe-off as a dashed line (where the curve's
cycles are its own side's foot's), and optionally a normative band (grey) read from a file
(:func:`read_normative`); one legend below the panels says which is which.

**Signs.** By default each curve has the model's sign: the lab coordinate's (``hip_flexion_r``: flexion +, its
moment flexor +; OpenSim's ``knee_angle_r``: extension +). ``clinical`` gives the signs of clinical gait reports,
from the joint's rotation in the sagittal plane, the model facing +x (OpenSim's convention, and casflex's
scenes'), z out of the page, each coordinate's moment along the child segment's rotation relative to the
parent's:

- hip: angle flexion + (the thigh turning +z), moment **extensor** + (-z);
- knee: angle flexion + (the shank turning -z relative to the thigh), moment **extensor** + (+z);
- ankle: angle dorsiflexion + (+z), moment **plantarflexor** + (-z).

So OpenSim's ``hip_flexion_r_moment`` and ``ankle_angle_r_moment`` change sign, ``knee_angle_r_moment`` keeps it,
and ``knee_angle_r`` changes sign (knee flexion +). A coordinate whose ``sign`` is -1 in the scene is turned
again. Other joints (trunk, arms) keep the model's sign, and their axis says so.

**Normative band file** (:func:`read_normative`): CSV with a header line ``load,percent,mean,sd,unit`` (in any
order; lines starting with ``#`` are comments), one row per load and percent of the gait cycle (0-100,
increasing per load; any number of points, drawn as given): ``load`` the panel's curve without its side
(``hip_flexion_moment`` for ``hip_flexion_r_moment`` and ``hip_flexion_l_moment``, ``knee_angle`` for the angle,
``knee.moment`` for a scene's own hinge ``knee_r``), ``mean`` and ``sd`` (>= 0) in ``unit``, which must be the
figure's (deg for an angle; N m, or N m/kg where the study normalises by mass, for a moment), in the figure's
sign convention.
"""

from __future__ import annotations

import csv
import math
import os
import re
import threading
from dataclasses import dataclass

import numpy as np
from matplotlib import collections
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import FixedLocator

from casflex.plotting import _axes
from casflex.plotting._figure import _new_figure, _save, render

__all__ = ["GaitFigures", "Normative", "gait_figure", "read_normative", "split_side", "sign_factor", "joint_title"]

#: Gait labs' colours: left red, right green; a curve of no side blue.
_COLOURS = {"left": "tab:red", "right": "tab:green", None: "tab:blue"}
#: The joints whose clinical sign is defined (module docstring): (angle's, moment's) factor on the rotation
#: about +z of the child segment relative to the parent, and what is positive.
_CLINICAL = {"hip": ((1.0, "flexion"), (-1.0, "extensor")), "knee": ((-1.0, "flexion"), (1.0, "extensor")),
             "ankle": ((1.0, "dorsiflexion"), (-1.0, "plantarflexor"))}
#: Joint titles of OpenSim's usual coordinates (the panel's key without "_moment"); others: the key's words.
_TITLES = {"hip_flexion": "Hip flexion/extension", "knee_angle": "Knee flexion/extension",
           "ankle_angle": "Ankle dorsi/plantarflexion", "lumbar_extension": "Lumbar flexion/extension",
           "pelvis_tilt": "Pelvic tilt", "arm_flex": "Shoulder flexion/extension", "elbow_flex": "Elbow flexion",
           "mtp_angle": "Toe (MTP) flexion", "subtalar_angle": "Subtalar angle", "hip": "Hip", "knee": "Knee",
           "ankle": "Ankle"}
#: the gait cycle's ticks (%)
_PERCENT_TICKS = (0, 20, 40, 60, 80, 100)
_SIDES = {"r": "right", "l": "left", "right": "right", "left": "left"}
_MOMENT = ("_moment", ".moment", "_force", ".force")


def split_side(name: str) -> tuple[str, str | None]:
    """(the name without its side, "left" / "right" / None): ``hip_flexion_r_moment`` -> (``hip_flexion_moment``,
    "right"), ``knee_l.moment`` -> (``knee.moment``, "left"), ``r_knee.angle``, ``knee.moment`` (no side)."""
    parts = re.split(r"([_.])", name)
    for i in range(0, len(parts), 2):  # the words; the separators between them at odd places
        side = _SIDES.get(parts[i].lower())
        if side is not None and len(parts) > 1:
            start = i - 1 if i > 0 else i  # the word and one separator beside it
            del parts[start:start + 2]
            return "".join(parts), side
    return name, None


def _joint(key: str) -> str | None:
    found = re.search(r"(?:^|[_.])(hip|knee|ankle)(?=[_.]|$)", key.lower())
    return found.group(1) if found else None


def is_moment(name: str) -> bool:
    return name.endswith(_MOMENT)


def _base(key: str) -> str:
    """The joint's key: the name without side and without its load's suffix (``hip_flexion``, ``knee``)."""
    for suffix in (*_MOMENT, ".angle"):
        key = key.removesuffix(suffix)
    return key


def joint_title(key: str) -> str:
    """The joint's title of a panel key (a name without its side): ``hip_flexion_moment`` -> "Hip
    flexion/extension"."""
    base = _base(key)
    return _TITLES.get(base) or re.sub(r"[_.]+", " ", base).strip().capitalize()


_MODEL = "the model's sign"


def sign_factor(name: str, clinical: bool, coordinate_sign: float = 1.0) -> tuple[float, str]:
    """(the factor the curve ``name`` is drawn with, what its positive values are) under the model's or the
    clinical signs (module docstring); ``coordinate_sign``: the scene coordinate's ``sign`` (lab names)."""
    joint = _joint(split_side(name)[0])
    if not clinical or joint is None:
        return 1.0, _MODEL
    factor, positive = _CLINICAL[joint][1 if is_moment(name) else 0]
    return factor * coordinate_sign, positive


@dataclass(frozen=True)
class Normative:
    """A normative band of one panel key: ``percent`` (n,) of the gait cycle, its ``mean`` and ``sd`` (n,) in
    ``unit``."""

    percent: np.ndarray
    mean: np.ndarray
    sd: np.ndarray
    unit: str


_COLUMNS = ("load", "percent", "mean", "sd", "unit")


def _number(where: str, field: str, text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise ValueError(f"{where}: {field}: expected a number, got {text!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{where}: {field}: expected a finite number, got {text!r}")
    return v


def read_normative(path: str | os.PathLike[str], units: dict[str, str] | None = None) -> dict[str, Normative]:
    """The normative bands of the file ``path`` (module docstring), by panel key; ``units``: the unit each kind
    of curve must have ({"angle": "deg", "moment": "N m/kg"}), checked. ValueError naming the file, the line and
    the field of anything wrong."""
    rows: dict[str, list[tuple[float, float, float, str, int]]] = {}
    try:
        with open(path, encoding="utf-8", newline="") as f:
            lines = [(n, ln) for n, ln in enumerate(f, 1) if ln.strip() and not ln.lstrip().startswith("#")]
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot be read ({exc})") from None
    if not lines:
        raise ValueError(f"{path}: no header line {','.join(_COLUMNS)} and no rows")
    header = [h.strip().lower() for h in next(csv.reader([lines[0][1]]))]
    if missing := [c for c in _COLUMNS if c not in header]:
        raise ValueError(f"{path}: line {lines[0][0]}: the header has no column {', '.join(missing)}; expected "
                         f"{','.join(_COLUMNS)}")
    for n, cells in ((n, next(csv.reader([ln]))) for n, ln in lines[1:]):
        where = f"{path}: line {n}"
        if len(cells) != len(header):
            raise ValueError(f"{where}: {len(cells)} cells, the header has {len(header)}")
        cell = dict(zip(header, (c.strip() for c in cells), strict=True))
        p, mean, sd = (_number(where, k, cell[k]) for k in ("percent", "mean", "sd"))
        if not 0.0 <= p <= 100.0:
            raise ValueError(f"{where}: percent: must lie in 0..100 (% of the gait cycle), got {p:g}")
        if sd < 0:
            raise ValueError(f"{where}: sd: must be >= 0 (one standard deviation), got {sd:g}")
        kind = "moment" if is_moment(cell["load"]) else "angle"
        if units and cell["unit"] != units[kind]:
            raise ValueError(f"{where}: unit: the figures draw {cell['load']!r} (a {kind}) in {units[kind]}, the file "
                             f"says {cell['unit']!r}; give the band in {units[kind]}")
        if split_side(cell["load"])[1] is not None:
            raise ValueError(f"{where}: load: {cell['load']!r} names a side; give it without (one band for both: "
                             f"{split_side(cell['load'])[0]!r})")
        rows.setdefault(cell["load"], []).append((p, mean, sd, cell["unit"], n))
    out = {}
    for key, r in rows.items():
        p = np.array([x[0] for x in r])
        if len(r) < 2 or np.any(np.diff(p) <= 0):
            bad = r[1 + int(np.argmax(np.diff(p) <= 0))][4] if len(r) >= 2 else r[0][4]
            raise ValueError(f"{path}: line {bad}: percent: {key!r} needs two or more points with increasing "
                             "percents")
        out[key] = Normative(p, np.array([x[1] for x in r]), np.array([x[2] for x in r]), r[0][3])
    return out


def _mean_sd(curves: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c = np.atleast_2d(curves)
    return c.mean(axis=0), c.std(axis=0, ddof=1) if c.shape[0] > 1 else np.zeros(c.shape[1])


def _curve(percent, curves: dict[str, np.ndarray], toe_off: dict[str, list[float]], factors: dict[str, float],
           what: str, name: str) -> tuple[np.ndarray, np.ndarray, str, float | None, str | None]:
    """One curve's band as drawn: (mean, sd, the band's label, the mean toe-off or None, its label)."""
    side = split_side(name)[1]
    c = np.atleast_2d(curves[name]) * factors.get(name, 1.0)
    who = (side or "mean").capitalize()
    mean, sd = _mean_sd(c)
    label = f"{who}: mean +- 1 SD ({c.shape[0]} {what if c.shape[0] > 1 else what[:-1]})"
    offs = [v for v in toe_off.get(name, []) if v is not None]
    if not offs:
        return mean, sd, label, None, None
    toe = f"{side.capitalize() + ' t' if side else 'T'}oe-off ({np.mean(offs):.0f} %)"
    return mean, sd, label, float(np.mean(offs)), toe


def _panel(ax, percent, names: list[str], curves: dict[str, np.ndarray], toe_off: dict[str, list[float]],
           factors: dict[str, float], what: str, norm: Normative | None, artists: dict[str, tuple]) -> None:
    """The panel's bands, means and toe-offs; ``artists``: name -> (its band, its mean's line, its toe-off's
    line or None), filled (:class:`GaitFigures` draws the next figure over them)."""
    if norm is not None:
        ax.fill_between(norm.percent, norm.mean - norm.sd, norm.mean + norm.sd, color="0.6", alpha=0.35, lw=0,
                        label="normative mean +- 1 SD")
    for name in names:
        colour = _COLOURS[split_side(name)[1]]
        mean, sd, label, off, off_label = _curve(percent, curves, toe_off, factors, what, name)
        band = ax.fill_between(percent, mean - sd, mean + sd, color=colour, alpha=0.2, lw=0)
        line, = ax.plot(percent, mean, color=colour, label=label)
        toe = None if off is None else ax.axvline(off, color=colour, ls="--", lw=1.0, label=off_label)
        artists[name] = (band, line, toe)
    ax.axhline(0.0, color="0.6", lw=0.6)
    ax.grid(True, alpha=0.3)
    ax.set_xlim(0, 100)
    # the ticks matplotlib's locator finds, not looked for at each draw
    ax.xaxis.set_major_locator(FixedLocator(_PERCENT_TICKS))


@dataclass(frozen=True)
class _Arrangement:
    """What a gait figure's panels are (one row per joint, its angle and moment): two figures of the same
    :attr:`shape` have the same panels, titles, axis labels, curves and toe-off lines, their data apart."""

    order: list[str]  # the joints, top to bottom
    joints: dict[str, dict[str, str]]  # joint -> {"angle": panel key, "moment": panel key}
    names: dict[str, list[str]]  # panel key -> its curves, sorted
    factors: dict[str, float]  # curve -> its sign's factor
    ylabels: dict[str, str]  # panel key -> its y axis's label
    shape: tuple


def _arrange(percent, curves: dict[str, np.ndarray], toe_off: dict[str, list[float]], units: dict[str, str],
             clinical: bool, coordinate_signs: dict[str, float] | None, normative: dict[str, Normative] | None
             ) -> _Arrangement:
    keys: dict[str, list[str]] = {}
    for name in curves:
        keys.setdefault(split_side(name)[0], []).append(name)
    joints: dict[str, dict[str, str]] = {}  # joint key -> {"angle": panel key, "moment": panel key}
    for key in keys:
        joints.setdefault(_base(key), {})["moment" if is_moment(key) else "angle"] = key
    order = sorted(joints, key=lambda j: (["hip", "knee", "ankle"].index(_joint(j)) if _joint(j) else 3, j))
    signs = coordinate_signs or {}
    factors, positive = {}, {}
    for name in curves:  # a lab moment's sign is its coordinate's (hip_flexion_r_moment: hip_flexion_r's)
        factors[name], positive[split_side(name)[0]] = sign_factor(name, clinical,
                                                                   signs.get(name.removesuffix("_moment"), 1.0))
    ylabels = {key: f"{units[names[0]]} ({positive[key] if positive[key] == _MODEL else positive[key] + ' +'})"
               for key, names in keys.items()}
    norms = {k: (n.percent.tobytes(), n.mean.tobytes(), n.sd.tobytes()) for k, n in (normative or {}).items()
             if k in keys}
    has_toe = {n: any(v is not None for v in toe_off.get(n, [])) for n in curves}
    shape = (tuple(order), tuple((j, tuple(sorted(joints[j].items()))) for j in order),
             tuple((k, tuple(sorted(v)), ylabels[k]) for k, v in sorted(keys.items())), tuple(sorted(has_toe.items())),
             tuple(sorted(norms.items())), np.asarray(percent, dtype=float).tobytes())
    return _Arrangement(order, joints, {k: sorted(v) for k, v in keys.items()}, factors, ylabels, shape)


def _legend(fig: Figure, h: float) -> None:
    """One legend for the figure, each label once (a panel's normative band too), below the panels."""
    seen: dict[str, object] = {}
    for ax in fig.axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            seen.setdefault(label, handle)
    fig.legend(list(seen.values()), list(seen), loc="lower center", bbox_to_anchor=(0.5, 0.05 / h), ncols=3,
               fontsize="small")


@dataclass
class _Drawn:
    """A drawn gait figure and its curves' artists by (panel key, curve)."""

    fig: Figure
    shape: tuple
    height: float
    artists: dict[tuple[str, str], tuple]


def _build(percent, curves: dict[str, np.ndarray], toe_off: dict[str, list[float]], title: str, what: str,
           arr: _Arrangement, normative: dict[str, Normative] | None) -> _Drawn:
    h = 2.7 * len(arr.order) + 0.6
    fig = _new_figure((9.0, h), layout=None)  # laid out by hand: the constrained layout took 40 % of the figure's time
    fig.subplots_adjust(left=0.8 / 9.0, right=1 - 0.15 / 9.0, top=1 - 0.55 / h, bottom=1.25 / h, wspace=0.3,
                        hspace=0.62 / 2.1)
    axes = np.atleast_2d(fig.subplots(len(arr.order), 2, squeeze=False, subplot_kw={"axes_class": _axes.Axes}))
    artists: dict[tuple[str, str], tuple] = {}
    for row, joint in zip(axes, arr.order, strict=True):
        for ax, kind in zip(row, ("angle", "moment"), strict=True):
            key = arr.joints[joint].get(kind)
            if key is None:
                ax.set_visible(False)
                continue
            mine: dict[str, tuple] = {}
            _panel(ax, percent, arr.names[key], curves, toe_off, arr.factors, what, (normative or {}).get(key), mine)
            artists |= {(key, name): a for name, a in mine.items()}
            _rescale(ax)
            # the title's height given (the axes' top, where matplotlib puts it with no tick label above): else
            # each draw measures the panel's tick labels to place it, 15 % of the figure's CPU for the same pixels
            ax.set_title(f"{joint_title(joint)} {kind}", y=1.0)
            ax.set_ylabel(arr.ylabels[key])
    for column in axes.T:  # the x axis's numbers and name under each column's lowest panel: the same 0-100 % above
        shown = [ax for ax in column if ax.get_visible()]
        for ax in shown[:-1]:
            ax.tick_params(axis="x", labelbottom=False)
        if shown:
            shown[-1].set_xlabel("gait cycle (%)")
    _legend(fig, h)
    fig.suptitle(title, y=1 - 0.2 / h, va="center")
    return _Drawn(fig, arr.shape, h, artists)


def gait_figure(percent: np.ndarray, curves: dict[str, np.ndarray], toe_off: dict[str, list[float]], title: str,
                path: str | os.PathLike[str], *, units: dict[str, str], what: str = "cycles", clinical: bool = False,
                coordinate_signs: dict[str, float] | None = None, normative: dict[str, Normative] | None = None
                ) -> Figure:
    """One row per joint: its angle (left) and moment (right) over ``percent`` (0-100 % of the gait cycle), the
    sides overlaid (module docstring), written to ``path``; returns the figure.

    ``curves``: name (``hip_flexion_r``, ``hip_flexion_r_moment``) -> (m, 101) in ``units[name]``, ``what``
    saying what the m rows are ("cycles", "subjects"); ``toe_off``: name -> the rows' toe-offs (%); ``clinical``:
    the clinical signs (module docstring; ``coordinate_signs``: the scene coordinates' signs by name);
    ``normative``: a band per panel key (:func:`read_normative`)."""
    arr = _arrange(percent, curves, toe_off, units, clinical, coordinate_signs, normative)
    fig = _build(percent, curves, toe_off, title, what, arr, normative).fig
    _save(fig, path)
    return fig


#: where this matplotlib lets a drawn figure take other data (a band's set_data, the data limits of collections
#: recomputed): else :class:`GaitFigures` draws each figure anew
_REUSABLE = (hasattr(getattr(collections, "FillBetweenPolyCollection", None), "set_data")
             and hasattr(Axes, "_update_collection_limits"))


class GaitFigures:
    """Gait figures drawn one after another (a study's subjects'), each rendered into PNG bytes: a figure of the
    same shape as the previous one (the same panels, curves and toe-off lines: :class:`_Arrangement`) is drawn
    over it, its data, labels and title replaced, its axes, ticks and texts kept (a new figure: 0.2 s to build
    and its 180 ticks made again at the first draw); the same pixels as :func:`gait_figure`'s. One per thread
    (:meth:`of_thread`): a figure is drawn in one thread at a time."""

    _threads = threading.local()

    def __init__(self) -> None:
        self._last: _Drawn | None = None

    @classmethod
    def of_thread(cls) -> GaitFigures:
        """The calling thread's :class:`GaitFigures` (made at its first call; figures may be drawn in several
        threads at once: a dask worker's with several threads, a study's command and its workers in one process)."""
        figures = getattr(cls._threads, "figures", None)
        if figures is None:
            figures = cls._threads.figures = cls()
        return figures

    def png(self, percent: np.ndarray, curves: dict[str, np.ndarray], toe_off: dict[str, list[float]], title: str,
            *, units: dict[str, str], what: str = "cycles", clinical: bool = False,
            coordinate_signs: dict[str, float] | None = None, normative: dict[str, Normative] | None = None
            ) -> bytes:
        """The PNG of :func:`gait_figure` of these arguments (its ``path`` apart)."""
        arr = _arrange(percent, curves, toe_off, units, clinical, coordinate_signs, normative)
        last = self._last
        if _REUSABLE and last is not None and last.shape == arr.shape:
            _redraw(last, percent, curves, toe_off, title, what, arr)
        else:
            self._last = last = None  # the previous figure freed before the next is built
            self._last = last = _build(percent, curves, toe_off, title, what, arr, normative)
        return render(last.fig)


def _rescale(ax) -> None:
    """The panel's y limits from its data as matplotlib's autoscale sets them (the data's span and the axes' margin
    on each side), computed from the data alone: matplotlib takes a line at y = 0 (``axhline``) through the data
    transform and back, whose last bits depend on the limits the panel had before, so a figure drawn over another
    had limits 3e-14 off a new one's, a few curve pixels one level apart. x is fixed at 0-100 %."""
    ys = [np.zeros(1)]  # the zero line
    ys += [path.vertices[:, 1] for coll in ax.collections for path in coll.get_paths()]  # the bands (normative too)
    ys += [np.asarray(line.get_ydata(), dtype=float) for line in ax.get_lines()
           if line.get_transform() == ax.transData]  # the means (not the toe-offs', in the axes' height)
    lo, hi = ax.yaxis.get_major_locator().nonsingular(np.nanmin(np.concatenate(ys)), np.nanmax(np.concatenate(ys)))
    margin = (hi - lo) * ax.margins()[1]
    ax.set_ylim(lo - margin, hi + margin)


def _redraw(drawn: _Drawn, percent, curves: dict[str, np.ndarray], toe_off: dict[str, list[float]], title: str,
            what: str, arr: _Arrangement) -> None:
    """``drawn`` (a figure of ``arr``'s shape) showing these curves: each band, mean and toe-off given its data and
    label, each panel's data limits recomputed from its artists, the legend made again, the title replaced."""
    for (_, name), (band, line, toe) in drawn.artists.items():
        mean, sd, label, off, off_label = _curve(percent, curves, toe_off, arr.factors, what, name)
        band.set_data(percent, mean - sd, mean + sd)
        line.set_data(percent, mean)
        line.set_label(label)
        if toe is not None:
            toe.set_xdata([off, off])
            toe.set_label(off_label)
    for ax in drawn.fig.axes:
        if ax.get_visible():
            _rescale(ax)
    for legend in list(drawn.fig.legends):
        legend.remove()
    _legend(drawn.fig, drawn.height)
    drawn.fig.suptitle(title, y=1 - 0.2 / drawn.height, va="center")
