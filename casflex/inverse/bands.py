"""How much of an inverse dynamics load is known: its bands (one standard deviation) from the anthropometry and
from the markers' noise.

- **Anthropometry.** The scene's ``[[uncertain]]`` properties (and those given as ``uncertain=``, replacing the
  scene's of the same target: :mod:`casflex.scene.uncertain`), e.g. a segment's mass and inertia from a table
  (10-20 %), become the last parameters of the inverse's model
  (:func:`~casflex.scene.uncertain.with_uncertain_estimated`). Each property's part is the first-order change of
  every load when it moves by its standard deviation, sd dL/dp_j, the derivative exact by AD
  (:mod:`casflex.inverse.load_jacobian`). At the fitted kinematics the rigid inverse's loads are linear in the
  bodies' masses and inertias (and in a torsion spring's stiffness and damping, a load's size, gravity): the part
  is then the whole change, (L(p + sd e_j) - L(p - sd e_j)) / 2. The second derivative is taken too and reported;
  where it is not 0 (a property the loads are not linear in: a centre of mass' position, where the scene takes it
  as a property, is quadratic, and the part is then still its central difference) the report names it. With
  independent priors, sd_anthropometry = sqrt(sum_j part_j^2).
- **Markers.** The markers' white noise (declared ``marker_noise``, m per axis, or the fit's residuals')
  propagated exactly to first order through the fit, the filter, the rates and the loads
  (:mod:`casflex.inverse.marker_band`); none where the coordinates were given instead of markers.
- **Total**: the root-sum-square of the two (the markers' noise and the tables' errors are independent).

Flexible segments (beams) are refused: their loads come from an HHT run, not linear in the properties, two runs a
property. What is not in a band: the segments' lengths and the joints' positions (geometry, not uncertain
properties), the plates' errors, soft tissue artefacts (marker errors correlated over frames).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from casflex.inverse.built import inverse_tree
from casflex.inverse.lab_names import lab_loads
from casflex.inverse.load_jacobian import LoadDerivatives, load_derivatives
from casflex.inverse.options import BandError, Bands
from casflex.inverse.plates import plate_loads
from casflex.inverse.rigid import rigid_loads
from casflex.inverse.tree import KinematicTree, kinematic_tree
from casflex.model import Model

__all__ = ["BandError", "BandSpec", "anthropometry", "band_spec", "inverse_bands", "marker_part"]

#: rigid_loads' outputs that are the motion, not loads
_MOTION = ("q", "qd", "qdd", "lam")
#: A property whose second derivative (difference) exceeds this fraction of its first is reported as not linear.
LINEAR = 1e-9


@dataclass(frozen=True)
class BandSpec:
    """The bands an inverse run computes: ``model`` the inverse's model with the uncertain properties as its last
    parameters (``index`` (n_u,) their places in p, ``targets`` their ``"<element>.<field>"``, ``sd`` (n_u,) their
    standard deviations in their units) and ``tree`` its kinematic tree; ``marker_noise`` m per axis (None: the
    fit's residuals'); ``given``: the coordinates were given (no marker fit, no markers' part)."""

    model: Model
    tree: KinematicTree
    targets: tuple[str, ...]
    sd: np.ndarray
    index: np.ndarray
    marker_noise: float | None
    given: bool

    def describe(self) -> dict:
        """The settings' record (JSON): each property's sd, the markers' noise asked."""
        return {"uncertain": {t: float(s) for t, s in zip(self.targets, self.sd, strict=True)},
                "marker_noise_m": self.marker_noise}


def _merged(scene, uncertain) -> object:
    """The scene with ``uncertain`` added to its own (:func:`casflex.scene.uncertain.declared_uncertain`)."""
    from casflex.scene.uncertain import declared_uncertain

    try:
        return declared_uncertain(scene, uncertain)
    except ValueError as exc:
        raise BandError("uncertain", str(exc)) from None


def band_spec(model: Model, tree: KinematicTree, bands: Bands, *, given: bool = False,
              n_markers: int = 0) -> BandSpec | None:
    """The bands asked (None: none), checked before any work (:class:`~casflex.inverse.options.Bands` checks its
    own fields). ``bands.asked`` None: computed when the scene (or ``bands.uncertain``) declares an uncertain
    property of sd > 0 or the markers' noise (m) is given; True: always; False: never. ``given``: the coordinates
    were given (no marker fit); ``n_markers``: the scene's markers the fit weighs (their channels must outnumber the
    coordinates to estimate the noise). :class:`BandError` (a ValueError) in one line otherwise."""
    from casflex.model import assembled
    from casflex.scene.uncertain import nuisance_names, with_uncertain_estimated

    if bands.asked is False:
        return None
    uncertain, marker_noise = bands.uncertain, bands.marker_noise
    if model.n_con != model.n_dof - tree.n and (bands.asked or uncertain or marker_noise is not None
                                                or model.scene.uncertain):
        beams = [b.name for b in model.scene.beams][:3]
        raise BandError("bands", f"for rigid segments only: the beams {beams} make this a flexible inverse (an HHT "
                                 "run), whose loads are not linear in the properties; not done yet (bands=False, "
                                 "--no-bands: the loads alone)")
    scene = _merged(model.scene, uncertain)
    names = nuisance_names(scene)
    if bands.asked is None and not names and marker_noise is None:
        return None
    if marker_noise is not None:
        if given:
            raise BandError("marker_noise", "the coordinates were given: there is no marker fit for it to enter")
    elif not given and 2 * n_markers <= tree.n:
        raise BandError("marker_noise", f"the {n_markers} markers give no more channels than the {tree.n} coordinates: "
                                        "the fit leaves no residual to estimate their noise; declare it (m; 0: the "
                                        "markers taken as exact)")
    estimated = with_uncertain_estimated(scene)
    if not estimated.supports and model.inertia == estimated.run.inertia:  # the inverse's model: kept (.built)
        tree_u = inverse_tree(estimated, tree.root)
    else:
        tree_u = kinematic_tree(assembled(estimated, inertia=model.inertia), tree.root)
    model_u = tree_u.model
    index = np.array([model_u.parameter_names.index(n) for n in names], dtype=int)
    targets = tuple(u.target for u in scene.uncertain if u.name in names)
    sd = np.array([u.prior(scene.property_value(u.target))[1] for u in scene.uncertain if u.name in names])
    return BandSpec(model_u, tree_u, targets, sd, index, None if marker_noise is None else float(marker_noise), given)


def rigid_load_function(tree: KinematicTree, t: np.ndarray, plates, p: np.ndarray):
    """``loads(z, zd, zdd, p=p) -> {name: (k,)}``: the rigid inverse's loads (N, N m; :mod:`.rigid`, and the lab's
    names: :mod:`.lab_names`) at the frames t (k,) with the ``plates`` applied, for coordinates (k, n_z) each."""
    m = tree.model
    external = (lambda tt, q: plate_loads(m, list(plates), tt, q)) if plates else None

    def loads(z, zd, zdd, p=p):
        sol = rigid_loads(tree, t, z, zd, zdd, p, external)
        out = {k: v for k, v in sol.items() if k not in _MOTION}
        return out | lab_loads(m.scene, out)

    return loads


def anthropometry(spec: BandSpec, t: np.ndarray, z: np.ndarray, zd: np.ndarray, zdd: np.ndarray,
                  plates=(), function=None, *, derivatives: LoadDerivatives | None = None
                  ) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, float]]:
    """({target: {load: (k,)}}, {target: bend}): the change of every load (N, N m) at the frames t (k,) when each
    uncertain property moves by its standard deviation, at the coordinates z, z', z'' (k, n_z); ``bend``: the
    largest second change over the largest first (0 or round-off where the loads are linear in the property).
    The rigid inverse's loads (with the ``plates``): sd times their exact derivative, the bend from their second
    (:mod:`casflex.inverse.load_jacobian`; ``derivatives``: already taken at these frames with ``spec.tree`` and
    ``spec.index``). ``function(z, zd, zdd, p) -> {name: (k,)}``: other outputs of each frame's coordinates and of
    the properties p of ``spec.model`` (the muscles': :mod:`casflex.muscles.bands`), by central differences."""
    p0 = spec.model.p_nominal
    if not spec.targets:
        return {}, {}
    if function is None:
        d = derivatives if derivatives is not None else load_derivatives(spec.tree, t, plates, z, zd, zdd, p0,
                                                                         spec.index)
        parts, bend = {}, {}
        for j, (target, sd) in enumerate(zip(spec.targets, spec.sd, strict=True)):
            parts[target] = {k: sd * v[:, j] for k, v in d.props.items()}
            first = max(float(np.max(np.abs(2.0 * sd * v[:, j]))) for v in d.props.values())
            second = max(float(np.max(np.abs(sd * sd * v[:, j]))) for v in d.curvature.values())
            bend[target] = second / first if first > 0 else 0.0
        return parts, bend
    base = function(z, zd, zdd, p0)
    parts, bend = {}, {}
    for j, target, sd in zip(spec.index, spec.targets, spec.sd, strict=True):
        dp = np.zeros_like(p0)
        dp[j] = sd
        up, down = function(z, zd, zdd, p0 + dp), function(z, zd, zdd, p0 - dp)
        parts[target] = {k: 0.5 * (up[k] - down[k]) for k in base}
        first = max(float(np.max(np.abs(up[k] - down[k]))) for k in base)
        second = max(float(np.max(np.abs(up[k] + down[k] - 2.0 * base[k]))) for k in base)
        bend[target] = second / first if first > 0 else 0.0
    return parts, bend


def _anthropometry_lines(spec: BandSpec, bend: dict[str, float]) -> list[str]:
    if not spec.targets:
        return ["bands (1 SD): no uncertain property declared: the anthropometry's part is 0"]
    props = ", ".join(f"{t} (sd {s:.3g})" for t, s in zip(spec.targets, spec.sd, strict=True))
    bent = [t for t, b in bend.items() if b > LINEAR]
    worst = max(bend.values())
    lines = [f"bands (1 SD): anthropometry from {props}; the loads linear in "
             + (f"each (second derivatives within {worst:.1g} of the first)" if not bent else
                f"all but {bent}: their parts are first-order changes (second derivatives up to {worst:.2g})")]
    return lines


def inverse_bands(spec: BandSpec, inputs, fit, z: np.ndarray, zd: np.ndarray, zdd: np.ndarray,
                  names: list[str], function=None) -> tuple[dict, dict, list[str], dict]:
    """The bands of the loads ``names`` of an inverse run (module docstring): (bands {load: {"anthropometry",
    "markers", "total": (k,)}}, parts {target: {load: (k,)}}, report lines, settings), from its checked
    ``inputs`` (:class:`~casflex.inverse.inputs.InverseInputs`), its marker ``fit`` and its filtered coordinates
    z, z', z'' (k, n_z); ``function(z, zd, zdd, p) -> {name: (k,)}``: the outputs, as :func:`anthropometry`'s
    (default the rigid inverse's loads)."""
    t, plates = inputs.t, inputs.plates
    derivs = None  # the rigid loads' derivatives: taken once for both parts
    if function is None and (spec.targets or not (spec.given or spec.marker_noise == 0)):
        derivs = load_derivatives(spec.tree, t, plates, z, zd, zdd, spec.model.p_nominal, spec.index,
                                  kinematics=inputs.tree)
    parts, bend = anthropometry(spec, t, z, zd, zdd, plates, function, derivatives=derivs)
    lines = _anthropometry_lines(spec, bend)
    anth = {k: np.sqrt(sum(parts[g][k] ** 2 for g in parts)) if parts else np.zeros(t.size) for k in names}
    settings = spec.describe()
    outputs = None if function is None else (lambda z, zd, zdd: function(z, zd, zdd, spec.model.p_nominal))
    mark, more, noise = marker_part(spec, inputs, fit, z, zd, zdd, names, outputs, derivatives=derivs)
    lines += more
    settings |= noise
    bands = {k: {"anthropometry": anth[k], "markers": mark[k], "total": np.hypot(anth[k], mark[k])} for k in names}
    return bands, parts, lines, settings


def marker_part(spec: BandSpec, inputs, fit, z: np.ndarray, zd: np.ndarray, zdd: np.ndarray, names: list[str],
                outputs=None, step: float = 1e-5, *, derivatives: LoadDerivatives | None = None
                ) -> tuple[dict[str, np.ndarray], list[str], dict]:
    """({name: (k,)}, report lines, settings): the markers' part of the bands (module docstring; 0 where the
    coordinates were given or the markers declared exact) of the rigid inverse's loads, by their exact derivatives
    along z, z', z'' (:mod:`casflex.inverse.load_jacobian`; ``derivatives``: already taken at these frames), or of
    ``outputs(z, zd, zdd) -> {name: (k,)}``, differenced by ``step`` along z (:func:`~.marker_band.load_jacobians`)."""
    from casflex.inverse.marker_band import fit_covariances, load_jacobians, marker_band, residual_noise

    t, plates = inputs.t, inputs.plates
    lines, settings = [], {}
    if spec.given or spec.marker_noise == 0:
        mark = {k: np.zeros(t.size) for k in names}
        why = "the coordinates were given, their noise is not known" if spec.given else \
            "the markers declared exact (marker_noise 0)"
        lines.append(f"bands: {why}: the markers' part is left out (0)")
    else:
        declared = spec.marker_noise is not None
        sigma = spec.marker_noise if declared else residual_noise(inputs.tree, fit)
        C = fit_covariances(inputs.tree, fit, inputs.y, sigma)
        if outputs is not None:
            D = load_jacobians(outputs, z, zd, zdd, names, step=step)
        else:
            d = derivatives if derivatives is not None else load_derivatives(inputs.tree, t, plates, z, zd, zdd,
                                                                             inputs.model.p_nominal)
            D = d.jacobians(names)
        sd = marker_band(t, np.isfinite(fit.rms), C, D, inputs.cutoff, inputs.settings.get("filter", "butterworth"))
        mark = {k: sd[:, i] for i, k in enumerate(names)}
        settings = {"marker_noise_m": sigma, "marker_noise_from": "declared" if declared else "residuals"}
        source = "declared" if declared else "the fit's residuals"
        lines.append(f"bands: markers' noise {1e3 * sigma:.2f} mm per axis ({source}; white, independent between "
                     "markers and frames) through the fit, the filter and the loads, to first order")
    return mark, lines, settings
