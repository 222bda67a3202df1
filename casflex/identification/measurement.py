"""The measurement model of output-error identification: what was recorded, when, and what is
known of the recording's initial state.

An :class:`Experiment` is one recording (a :class:`~casflex.data.MeasurementSet`): channels are
model dofs sampled at their own times (any rate, irregular, NaN for a missing sample); the
model's clock starts at the first sample. The model is stepped on its own grid t0 + k dt and its
outputs are interpolated at the sample times by the cubic Hermite through q and q' at the ends
of the step that holds the sample (:class:`SampleMap`), which is what the trapezoidal rule
integrates between two steps.

The initial state is ``"scene"`` (the scene's q0, qd0 at the first sample), ``"velocities"``
(the scene's q0, velocities estimated: the positions are trusted) or ``"estimate"`` (both
estimated): :mod:`.initial_state`.

:func:`check_against_scene` stops before any fit when data and scene cannot belong together
(positions in millimetres, times in milliseconds, a recording that does not start where the
scene starts), with one line that says what to do.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from casflex.data import MeasurementSet
from casflex.identification.choices import INITIAL_STATES  # noqa: F401 (re-exported)
from casflex.model import Model
from casflex.model.markers import channel_index, channel_values, marker_channels

__all__ = ["Experiment", "SampleMap", "INITIAL_STATES", "check_against_scene", "check_units", "check_frozen",
           "free_dofs", "nyquist"]



@dataclass(frozen=True, eq=False)
class Experiment:
    """One recording to fit.

    Attributes
    ----------
    data : MeasurementSet
        Positions (m, rad) of some model dofs at times t (s); NaN marks a missing sample.
    initial_state : {"scene", "velocities", "estimate"}
        What is known of the state at the first sample (module docstring).
    channels : tuple of str, optional
        The compared channels (model dof names, markers' channels); default every channel of the data.
    noise : float or {channel: float}, optional
        Standard deviation of the measurement noise, if known: one value for every channel (m;
        rotations compared as arc lengths at the scene's size) or one per compared channel (in the
        channel's unit, m or rad). It weights the channels and is checked against the residuals.
        Default: each channel's noise estimated from the residuals (:mod:`.estimate`).
    name : str
        Reported with the experiment's results.
    loss_weights : (n_samples, n_compared_channels) array in (0, 1], optional
        Each sample's weight from a robust loss (:mod:`.estimate`, ``loss``): its noise counts as
        noise / sqrt(weight). Set by the fit; default every sample at full weight.
    """

    data: MeasurementSet
    initial_state: str = "scene"
    channels: tuple[str, ...] | None = None
    noise: float | Mapping[str, float] | None = None
    name: str = ""
    loss_weights: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.initial_state not in INITIAL_STATES:
            raise ValueError(f"initial_state: expected one of {INITIAL_STATES}, got {self.initial_state!r}")
        values = self.noise.items() if isinstance(self.noise, Mapping) else [("", self.noise)]
        for c, v in values:
            if v is not None and not (isinstance(v, (int, float, np.floating)) and np.isfinite(v) and v > 0):
                where = f"noise[{c!r}]" if c else "noise"
                raise ValueError(f"{where}: expected a standard deviation > 0 (m, rad), got {v!r}")
        if self.data.t.size < 2:
            raise ValueError("data: output-error identification needs a time series (at least 2 samples)")

    def noise_of(self, channel: str) -> float | None:
        """The declared noise of ``channel`` (None: not declared)."""
        return self.noise.get(channel) if isinstance(self.noise, Mapping) else self.noise

    def noise_level(self) -> float | None:
        """The largest declared noise (None: not declared)."""
        return max(self.noise.values()) if isinstance(self.noise, Mapping) else self.noise

    def compared(self, model: Model) -> tuple[str, ...]:
        """The compared channels, checked against the model and the data."""
        self.data.select(model)  # unknown channel names raise here
        names = tuple(self.channels) if self.channels is not None else self.data.channels
        markers = marker_channels(model)
        for c in names:
            if c not in model.dof_names and c not in markers:
                raise ValueError(f"dofs: unknown dof {c!r}; the model's dofs are {list(model.dof_names)}"
                                 + (f", its markers' channels {list(markers)}" if markers else ""))
            if c not in self.data.channels:
                raise ValueError(f"dofs: {c!r} is not in the data (channels: {list(self.data.channels)})")
        if not names:
            raise ValueError("dofs: no channel to compare")
        empty = [c for c in names if not np.isfinite(self.data.q[:, self.data.channels.index(c)]).any()]
        if empty:  # a marker never seen: nothing to compare, and no first sample to check or start from
            raise ValueError(f"{_label(self.data)}: channel {empty[0]!r} has no sample (every value is NaN); drop it "
                             "from the file or leave it out of the compared channels (--dofs)")
        if isinstance(self.noise, Mapping):
            extra = [c for c in self.noise if c not in names]
            missing = [c for c in names if c not in self.noise]
            if extra or missing:
                what = f"{extra[0]!r} is not a compared channel" if extra else f"no value for {missing[0]!r}"
                raise ValueError(f"noise: {what}; give one standard deviation per compared channel "
                                 f"({', '.join(names)})")
        return names


def nyquist(experiment: Experiment) -> float:
    """The Nyquist circular frequency (rad/s) of the recording's median sample spacing."""
    return float(np.pi / np.median(np.diff(experiment.data.t)))


def free_dofs(model: Model) -> np.ndarray:
    """Indices of the dofs no support fixes (the unknowns of an estimated initial state)."""
    fixed = {c.dof for c in model.constraints}
    return np.array([i for i in range(model.n_dof) if i not in fixed], dtype=int)


@dataclass(frozen=True, eq=False)
class SampleMap:
    """Every finite sample of an experiment as an interpolation of the model's step-end states.

    The model steps from ``t0`` (the first sample) in ``n_steps`` steps of ``dt`` (s), past the
    last sample. Observation j is channel ``channel[j]`` (model dof ``dof[j]``; from n_dof on a
    marker's coordinate, :func:`casflex.model.markers.channel_index`) measured ``y[j]`` at ``time[j]``,
    in step ``step[j]`` (from t_k = t0 + k dt) at s = (t - t_k)/dt, and the model predicts
    w0 q_k + w1 q'_k + w2 q_k+1 + w3 q'_k+1 with ``weights[j]`` = (h00, dt h10, h01, dt h11), the
    cubic Hermite basis at s.
    """

    t0: float
    dt: float
    n_steps: int
    channels: tuple[str, ...]
    channel: np.ndarray
    dof: np.ndarray
    time: np.ndarray
    y: np.ndarray
    step: np.ndarray
    weights: np.ndarray
    sample: np.ndarray  # observation j is sample ``sample[j]`` of the data (its row in data.t)

    @classmethod
    def of(cls, model: Model, experiment: Experiment, dt: float) -> SampleMap:
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt: must be a positive number of seconds, got {dt!r}")
        data = experiment.data
        names = experiment.compared(model)
        cols = [data.channels.index(c) for c in names]
        t0 = float(data.t[0])
        n_steps = max(1, int(np.ceil((data.t[-1] - t0) / dt - 1e-9)))
        Y = np.asarray(data.q, dtype=float)[:, cols]
        rows, ch = np.nonzero(np.isfinite(Y))
        if rows.size == 0:
            raise ValueError("data: no finite sample in the compared channels")
        time = data.t[rows]
        u = (time - t0) / dt
        step = np.clip(np.floor(u + 1e-9).astype(int), 0, n_steps - 1)
        s = np.clip(u - step, 0.0, 1.0)
        s[np.abs(s) < 1e-9] = 0.0
        weights = np.column_stack([2 * s**3 - 3 * s**2 + 1, dt * (s**3 - 2 * s**2 + s),
                                   -2 * s**3 + 3 * s**2, dt * (s**3 - s**2)])
        dof = np.array([channel_index(model, n) for n in names], dtype=int)[ch]  # >= n_dof: a marker's
        return cls(t0, float(dt), n_steps, names, ch, dof, time, Y[rows, ch], step, weights, rows)

    @property
    def needed_steps(self) -> np.ndarray:
        """The step-end indices (0 .. n_steps) whose states the observations use."""
        return np.unique(np.concatenate([self.step, self.step + 1]))

    def predict(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Model outputs (m,) from the channels' values and rates at the step ends (n_steps + 1,
        n_channels; :func:`casflex.model.markers.channel_values`)."""
        k, d, w = self.step, self.dof, self.weights
        return w[:, 0] * q[k, d] + w[:, 1] * qd[k, d] + w[:, 2] * q[k + 1, d] + w[:, 3] * qd[k + 1, d]


# -- checks ------------------------------------------------------------------------------------

def _rest_velocity(data: MeasurementSet, cols: list[int], m: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """Velocity at the first sample of each channel ``cols`` from a quadratic fitted through the
    first ``m`` finite samples, and its standard error (from the fit's residuals, with a floor
    of the noise a position can carry, 1e-6 of its magnitude)."""
    v, se = np.zeros(len(cols)), np.full(len(cols), np.inf)
    for j, c in enumerate(cols):
        ok = np.flatnonzero(np.isfinite(data.q[:, c]))[:m]
        if ok.size < 4:
            continue
        tt = data.t[ok] - data.t[0]
        A = np.column_stack([np.ones_like(tt), tt, tt**2])
        coef, *_ = np.linalg.lstsq(A, data.q[ok, c], rcond=None)
        res = data.q[ok, c] - A @ coef
        s2 = max(float(res @ res) / (ok.size - 3), (1e-6 * np.abs(data.q[ok, c]).max()) ** 2)
        v[j] = coef[1]
        se[j] = np.sqrt(s2 * np.linalg.inv(A.T @ A)[1, 1])
    return v, se


#: A recording "starts moving" when its first velocity exceeds this fraction of its typical speed.
MOVING = 0.2


def _speed(data: MeasurementSet, cols: list[int]) -> float:
    """The recording's typical speed (m/s): the 90th percentile of |dy/dt| over every channel
    and sample interval."""
    rates = [np.abs(np.diff(data.q[:, c]) / np.diff(data.t)) for c in cols]
    rates = np.concatenate([r[np.isfinite(r)] for r in rates])
    return float(np.percentile(rates, 90)) if rates.size else 0.0


def _label(data: MeasurementSet) -> str:
    """What a message calls the recording: its file (one of several --data), else "data"."""
    return str(data.meta.get("path", "data")) if data.source == "file" else "data"


def check_units(model: Model, data: MeasurementSet, names: Sequence[str] | None = None) -> None:
    """ValueError with one line when the recording's channels ``names`` (default all) are not in the
    scene's units: positions that reach 30 times the scene's size (millimetres, centimetres), or
    times that look like milliseconds (every method's check: docs/identification.md, step 1)."""
    scene = model.scene
    names = data.channels if names is None else names
    cols = [data.channels.index(c) for c in names if not c.startswith("theta")]
    span = scene.length_scale
    reach = max(span, max(abs(v) for n in scene.nodes for v in (n.x, n.y)))
    finite = [c for c in cols if np.isfinite(data.q[:, c]).any()]
    if finite:
        big = float(np.nanmax(np.abs(data.q[:, finite])))
        if big > 30 * reach:
            factor = 1000 if big > 300 * reach else 100
            unit = "millimetres" if factor == 1000 else "centimetres"
            raise ValueError(f"{_label(data)}: positions reach {big:.4g} while the scene spans {span:.3g} m: they look "
                             f"like {unit} (x {factor}); give positions in metres")
    t = data.t
    if t.size < 2:
        return
    dt_med = float(np.median(np.diff(t)))
    span, run = t[-1] - t[0], max(scene.run.t_end, 1.0)
    # a recording of a tenth of the scene's run in ms spans 100 runs; a shorter one, sampled at 1 kHz or slower,
    # spans over 10 runs at a sample per second or slower (0.3 s of twobar: 300 "s", 300 000 model steps)
    if (span > 100 * run and dt_med >= 0.1) or (span > 10 * run and dt_med >= 1.0):
        raise ValueError(f"{_label(data)}: t runs from {t[0]:g} to {t[-1]:g} in steps of {dt_med:g}: the times look "
                         f"like milliseconds (the scene's run lasts {scene.run.t_end:g} s); give t in seconds")


#: A channel holding one value at this many samples or more, while others move, is taken for a frozen one
FROZEN_SAMPLES = 10


def check_frozen(model: Model, data: MeasurementSet, names: Sequence[str] | None = None) -> None:
    """ValueError with one line for a channel (of ``names``, default all the model knows) that holds one value,
    to the last digit, at every one of its samples (at least FROZEN_SAMPLES) while another channel moves: a
    marker frozen or filled by the capture software. Only channels the model's free dofs move, at another value
    than the scene's own (a symmetric scene's noise-free run keeps a dof at its initial value: that passes).
    Fitted, twobar's y3 frozen gave the adapted direct method success with k3 = 198 +- 17 for 400."""
    names = [c for c in (data.channels if names is None else names) if c in data.channels]
    known = [c for c in names if c in model.dof_names or c in marker_channels(model)]
    moving = [c for c in data.channels if _finite(data, c).size and np.ptp(_finite(data, c)) > 0]
    q0 = channel_values(model, model.q0, model.qd0)[0][0]
    free = free_dofs(model)
    nudged = channel_values(model, model.q0 + 1e-6 * np.eye(model.n_dof)[free], np.zeros((free.size, model.n_dof)))[0]
    can_move = np.abs(nudged - q0).max(axis=0, initial=0.0) > 0  # a support's dof, a marker on a clamped body: never
    for c in known:
        y = _finite(data, c)
        if y.size < FROZEN_SAMPLES or np.ptp(y) > 0 or not can_move[channel_index(model, c)] \
                or not [m for m in moving if m != c]:
            continue
        if abs(y[0] - q0[channel_index(model, c)]) <= 1e-12 * max(1.0, abs(y[0])):
            continue
        raise ValueError(f"{_label(data)}: channel {c!r} holds one value ({y[0]:.6g}) at all its {y.size} samples "
                         "while the others move: a frozen or filled marker? Drop it (--dofs, the indirect method) or "
                         "mend the recording")


def _finite(data: MeasurementSet, channel: str) -> np.ndarray:
    y = data.q[:, data.channels.index(channel)]
    return y[np.isfinite(y)]


def check_against_scene(model: Model, experiment: Experiment) -> None:
    """ValueError with one line when the data cannot belong to the scene: positions in other
    units than metres, times in milliseconds, or (for ``initial_state`` "scene" and
    "velocities") a first sample far from the scene's initial configuration, or (for "scene") a
    recording that starts moving while the scene starts at rest."""
    data, scene = experiment.data, model.scene
    names = experiment.compared(model)
    check_units(model, data, names)
    check_frozen(model, data, names)
    trans = [c for c in names if not c.startswith("theta")]
    cols = [data.channels.index(c) for c in trans]
    span = scene.length_scale
    t = data.t
    if experiment.initial_state == "estimate":
        return
    noise = experiment.noise_level() or 1e-3 * span
    tol = 0.01 * span + 5 * noise
    cols_all = [data.channels.index(c) for c in names]
    first = np.array([data.q[np.flatnonzero(np.isfinite(data.q[:, c]))[0], c] for c in cols_all])
    q0_all, qd0_all = (v[0] for v in channel_values(model, model.q0, model.qd0))
    scene_q = np.array([q0_all[channel_index(model, c)] for c in names])
    scale = np.array([1.0 if c.startswith("theta") else 1.0 / span for c in names])
    off = np.abs(first - scene_q) * scale
    j = int(np.argmax(off))
    if off[j] > tol / span:
        unit = "rad" if names[j].startswith("theta") else "m"
        raise ValueError(f"{_label(data)}: the recording does not start at the scene's initial state: {names[j]} = "
                         f"{first[j]:.4g} {unit} at the first sample (t = {t[0]:g} s), the scene has {scene_q[j]:.4g} "
                         f"{unit}; use --initial-state estimate")
    if experiment.initial_state == "scene" and cols:
        v, se = _rest_velocity(data, cols)
        v_scene = np.array([qd0_all[channel_index(model, c)] for c in trans])
        # against the recording's own speeds: a quadratic through the first samples of a release
        # from rest carries the jerk as a velocity (twobar at 0.5 mm noise: 0.085 m/s, its speeds 2 m/s)
        moving = (np.abs(v - v_scene) > 5 * se) & (np.abs(v - v_scene) > MOVING * _speed(data, cols))
        if moving.any():
            j = int(np.argmax(np.where(moving, np.abs(v - v_scene), 0.0)))
            raise ValueError(f"{_label(data)}: the recording starts moving ({trans[j]} at {v[j]:.3g} m/s at t = "
                             f"{t[0]:g} s) while the scene starts at {v_scene[j]:.3g} m/s; use --initial-state "
                             "velocities (positions trusted) or estimate")
