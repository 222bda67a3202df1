"""Whether an identified model explains a recording: its residuals channel by channel and the rules
of the default path (:mod:`.estimate`, step 7), on plain arrays, for the NLP transcription
(:mod:`.shooting_nlp`), whose own optimum may be a local minimum with the joins of its intervals
open, where single shooting of the identified model leaves the data.

Per experiment and compared channel: the residual analysis (:func:`.statistics.residual_analysis`:
RMS, autocorrelation, Ljung-Box whiteness), the fit 1 - |r| / |y - mean y| and the motion and
residual in noise units that the pooled fit adds up (:func:`pooled_fit`). The rules:
the pooled fit is at least :data:`FIT_THRESHOLD` or every moving channel's residual is
white; each channel's residual RMS is at most 3 x its declared noise.

The noise units: the declared noise (one value: rotations taken as arc lengths at the scene's
length scale l, as :class:`.output_error.OutputError` weighs them; or one value per channel),
or, undeclared, one weight for every channel (rotations again times l) unless the channels'
residual RMS in those weights differ by more than :data:`REWEIGHT`: then each channel's
own RMS, as the default path refits with (its step 3).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from casflex.identification.statistics import residual_analysis

__all__ = ["channel_residuals", "noise_units", "noise_record", "residual_reasons", "pooled_fit", "FIT_THRESHOLD",
           "REWEIGHT", "LONE_MISFIT"]

#: A recording fitted below this fraction of its measured motion (pooled, :func:`pooled_fit`) makes the result
#: implausible, unless its residuals are white.
FIT_THRESHOLD = 0.95
#: A channel of undeclared noise whose residual RMS is this many times the recording's median channel's (of its
#: kind: translations, rotations), structured and below FIT_THRESHOLD of its motion, is not explained by the model:
#: markers' noise differs by a few times between markers, not tenfold; weighted by its own RMS it counted for little
#: in the pooled fit (the knee pendulum's foot markers' labels swapped: residuals 0.11-0.13 m, 1 mm elsewhere)
LONE_MISFIT = 10.0
#: Channels of undeclared noise whose residual RMS (in the fit's weights) differ by more than this factor are
#: refitted weighted by it: below, weights that far off cost under 1 % of the estimates' variance
REWEIGHT = 1.2


def pooled_fit(residuals: dict) -> float | None:
    """An experiment's fit over all its moving channels in the fit's weights (noise units):
    1 - |r| / |y - mean y| with each channel's mean removed (None: no channel moves)."""
    moving = [ch for ch in residuals.values() if ch["fit"] is not None]
    motion = math.sqrt(sum(ch["motion_w"] ** 2 for ch in moving))
    return 1 - math.sqrt(sum(ch["residual_w"] ** 2 for ch in moving)) / motion if motion > 0 else None


def noise_units(names: list[str], rms: dict[str, float], rotation: np.ndarray, length_scale: float,
                declared: float | Mapping[str, float] | None) -> tuple[np.ndarray, bool]:
    """(sigma, estimated): each channel's noise unit (len(names),; m, rad) and whether it is the
    channel's own residual RMS (undeclared noise, channels apart by more than REWEIGHT).

    names : the compared channels; rms : {channel: residual RMS (m, rad)}; rotation : (len(names),)
    True for a rotation channel; length_scale : the scene's l (m); declared : the declared noise."""
    base = np.where(rotation, 1.0 / length_scale, 1.0)  # rotations as arc lengths at the scene's size
    if isinstance(declared, Mapping):
        return np.array([float(declared[c]) for c in names]), False
    if declared is not None:
        return base * float(declared), False
    own = np.array([rms.get(c, 0.0) for c in names])
    weighted = own / base
    if own.min(initial=0.0) > 1e-9 * length_scale and weighted.max() > REWEIGHT * weighted.min():
        return own, True
    return base, False


def channel_residuals(time: np.ndarray, channel: np.ndarray, names: list[str], y: np.ndarray, r: np.ndarray,
                      sigma: np.ndarray, length_scale: float, declared: float | Mapping[str, float] | None) -> dict:
    """Residual analysis and fit of every channel of one experiment (as the default path's record).

    time (m,) s, channel (m,) index into ``names``, y (m,) the measured values and r (m,) the model's
    minus them (m, rad), sigma (len(names),) each channel's noise unit (:func:`noise_units`).
    Returns {channel: residual_analysis's entry + "fit" (None: the channel does not move),
    "motion_w" and "residual_w" (|y - mean y| and |r| in noise units)}."""
    order = np.argsort(time, kind="stable")
    res = residual_analysis(r[order], channel[order], tuple(names), [np.arange(r.size)], declared)
    for c, name in enumerate(names):
        if name not in res:
            continue
        sel = channel == c
        spread = np.linalg.norm(y[sel] - y[sel].mean())
        # a channel that does not move (a supported dof) has no motion to reproduce: no fit measure
        still = spread <= 1e-9 * np.sqrt(sel.sum()) * max(length_scale, float(np.abs(y[sel]).max()))
        res[name]["fit"] = None if still else float(1 - np.linalg.norm(r[sel]) / spread)
        res[name]["motion_w"] = 0.0 if still else float(spread / sigma[c])
        res[name]["residual_w"] = float(np.linalg.norm(r[sel]) / sigma[c])
    return res


def noise_record(declared: float | Mapping[str, float] | None, estimated: bool, residuals: dict) -> dict:
    """What the channels' noise was taken to be (m, rad) and where it came from (as the default path records it)."""
    if declared is not None:
        values = declared if isinstance(declared, Mapping) else dict.fromkeys(residuals, declared)
        return {"source": "declared", "channels": dict(values)}
    source = ("estimated from the residuals, the channels weighted by it" if estimated else
              f"estimated from the residuals; one weight (the channels agree within a factor {REWEIGHT:g})")
    return {"source": source, "channels": {c: ch["rms"] for c, ch in residuals.items()}}


def residual_reasons(label: str, res: dict) -> list[str]:
    """Why experiment ``label``'s residuals (:func:`channel_residuals`) make the result implausible
    (empty: they do not): a pooled fit below FIT_THRESHOLD with a structured (not white) residual, or
    a residual RMS above 3 x the declared noise."""
    reasons = []
    pooled, structured = pooled_fit(res), [n for n, ch in res.items() if ch["fit"] is not None and not ch["white"]]
    # pooled over the channels in noise units: a channel that barely moves adds a sliver of motion and a residual at
    # its noise, and cannot decide; white residuals everywhere are noise, however low the fit
    if pooled is not None and pooled < FIT_THRESHOLD and structured:
        worst = max(structured, key=lambda n: res[n]["residual_w"])
        reasons.append(f"{label}: the model reproduces only {100 * pooled:.0f} % of the measured motion (all "
                       f"channels, in noise units) and leaves a structured residual, the largest on {worst} "
                       f"({100 * res[worst]['fit']:.0f} % of its motion): a local minimum, a wrong scene or a "
                       "model that misses the physics")
    reasons += _lone_misfits(label, res)
    for name, ch in res.items():
        ratio = ch.get("noise_ratio")
        if ratio is not None and ratio > 3:
            reasons.append(f"{label}: the residual RMS of {name} is {ratio:.1f} x the declared "
                           "noise: the model does not explain the data to the noise level")
    return reasons


def _lone_misfits(label: str, res: dict) -> list[str]:
    """Channels of undeclared noise that the model leaves unexplained beside the others (:data:`LONE_MISFIT`): the
    pooled fit weighs each channel by its own residual RMS, so one channel's misfit reads as its noise there."""
    bad, typical = {}, {}
    for rotation in (False, True):
        group = {n: ch for n, ch in res.items() if n.startswith("theta") == rotation and ch.get("noise_ratio") is None}
        if len(group) < 3:  # no typical channel to compare with
            continue
        median = float(np.median([ch["rms"] for ch in group.values()]))
        for name, ch in group.items():
            fit = ch.get("fit")
            if median > 0 and ch["rms"] > LONE_MISFIT * median and not ch["white"] and fit is not None \
                    and fit < FIT_THRESHOLD:
                bad[name], typical[name] = ch["rms"] / median, median
    if not bad:
        return []
    worst = max(bad, key=bad.get)
    return [f"{label}: the model does not explain {', '.join(bad)} (a structured residual, {bad[worst]:.0f} x the "
            f"median channel's RMS of {typical[worst]:.3g} on {worst}, {100 * res[worst]['fit']:.0f} % of its "
            "motion fitted): a channel or marker label of another point, or a motion the model lacks"]
