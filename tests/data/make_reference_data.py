"""Writes the reference motions in this folder: casflex's built-in scenes simulated by another code.

    python tests/data/make_reference_data.py        # needs Exudyn: pip install -e '.[peers]'

For each scene (the built-in twobar and threelink, and twobar_damped.toml here: twobar with dampers
in its joints), Exudyn (:mod:`casflex.peers.exudyn`: ANCF cable elements, generalized-alpha
without damping) simulates 0-4 s with 8 elements per beam and h = 1e-4 s, Newton increments to
1e-10, and every node's x, y, theta and their rates are kept at 1 kHz (``<scene>_exudyn.npz``:
keys t, channels, q, qd, meta). The file's own error is measured against a run with 16
elements per beam and h = 5e-5 s and recorded in ``meta`` (``error_xy``, m, and ``error_theta``, rad:
max over samples and channels). These are the "measurements" the identification tests and
``studies/realdata.py`` fit with casflex's own, different, discretisation. Without arguments it also
writes ``cantilever_damped_exudyn.npz`` (:func:`make_cantilever`), the check of beam damping, and
``twobar_markers_exudyn.npz`` (:func:`make_markers`), the check of markers on beams, and
``forms_exudyn.npz`` (:func:`make_forms`), recordings of other model forms than the scenes'.
"""

from __future__ import annotations

import io
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SCENES = ("twobar", "threelink", str(HERE / "twobar_damped.toml"))
T_END = 4.0


def make(scene_name: str) -> Path:
    import casflex
    from casflex.peers import exudyn
    from casflex.results import atomic_write_bytes

    scene = casflex.load_scene(scene_name)
    scene_name = Path(scene_name).stem
    data = exudyn.simulate(scene, T_END, elements=8, h=1e-4, sample_dt=1e-3)
    # (16 short elements: Newton increments reach 1e-9 only, not 1e-10)
    fine = exudyn.simulate(scene, T_END, elements=16, h=5e-5, sample_dt=1e-3, newton_tol=1e-9)
    error = np.abs(fine.q - data.q).max(axis=0)
    rot = np.array([c.startswith("theta") for c in data.channels])
    meta = {**data.meta, "error_xy": float(error[~rot].max()), "error_theta": float(error[rot].max()),
            "check": "against 16 elements per beam, h = 5e-5 s", "p": scene_name + " nominal"}
    buf = io.BytesIO()
    np.savez_compressed(buf, t=data.t, channels=np.array(data.channels), q=data.q, qd=data.qd,
                        meta=np.array(json.dumps(meta)))
    path = atomic_write_bytes(HERE / f"{scene_name}_exudyn.npz", buf.getvalue())
    print(f"{path.name}: {data.t.size} samples of {len(data.channels)} channels, own error {meta['error_xy']:.2e} m, "
          f"{meta['error_theta']:.2e} rad, {meta['code']}")
    return path


def _positions(toml: str, t_end: float) -> Path:
    """<toml stem>_exudyn.npz: the scene's motion over t_end s at 1 kHz, 8 elements per beam,
    h = 1e-4 s (keys t, channels, q, meta)."""
    import casflex
    from casflex.peers import exudyn
    from casflex.results import atomic_write_bytes

    data = exudyn.simulate(casflex.load_scene(HERE / toml), t_end, elements=8, h=1e-4, sample_dt=1e-3)
    buf = io.BytesIO()
    np.savez_compressed(buf, t=data.t, channels=np.array(data.channels), q=data.q,
                        meta=np.array(json.dumps(data.meta)))
    path = atomic_write_bytes(HERE / f"{Path(toml).stem}_exudyn.npz", buf.getvalue())
    print(f"{path.name}: {data.t.size} samples, {data.meta['code']}")
    return path


def make_cantilever() -> Path:
    """cantilever_damped_exudyn.npz: cantilever_damped.toml over 2 s (Exudyn's Kelvin-Voigt bending
    and axial damping beta EI, beta EA)."""
    return _positions("cantilever_damped.toml", 2.0)


def make_markers() -> Path:
    """twobar_markers_exudyn.npz: twobar_markers.toml (twobar with two markers off its bars' axes) over
    1 s: every node's and marker's x, y (Exudyn's MarkerBodyPosition)."""
    return _positions("twobar_markers.toml", 1.0)


#: Model forms other than the built-in scene's (studies/modelform.py): Exudyn's beam and a factor on every beam's E.
#: "ge": Exudyn's geometrically exact beam, with shear and the section's rotary inertia (casflex's beams without).
FORMS = {"twobar_rotary": ("twobar", "ge", 1.0), "twobar_rotary_stiff": ("twobar", "ge", 10.0),
         "twobar_soft": ("twobar", "ancf", 0.01), "twobar_rigid": ("twobar", "ancf", 1000.0),
         "threelink_rotary": ("threelink", "ge", 1.0)}
FORM_NODES = {"twobar": ("3", "5"), "threelink": ("3", "5", "7")}


def make_forms() -> Path:
    """forms_exudyn.npz: for every form of :data:`FORMS`, the positions of the markers' nodes
    (``<form>``: shape (301, 2 n), columns x, y per node of FORM_NODES) over 0-3 s at 100 Hz, 8 elements
    per beam, h = 1e-4 s; ``t`` and per form ``<form>_channels``."""
    import dataclasses

    import casflex
    from casflex.peers import exudyn
    from casflex.results import atomic_write_bytes

    arrays, meta = {}, {}
    for form, (name, beam, e_factor) in FORMS.items():
        scene = casflex.load_scene(name)
        scene = dataclasses.replace(scene, beams=tuple(dataclasses.replace(b, E=b.E * e_factor) for b in scene.beams))
        data = exudyn.simulate(scene, 3.0, elements=8, h=1e-4, sample_dt=1e-2, beam=beam)
        names = [f"{c}{n}" for n in FORM_NODES[name] for c in ("x", "y")]
        arrays["t"] = data.t
        arrays[form] = data.q[:, [data.channels.index(c) for c in names]]
        arrays[f"{form}_channels"] = np.array(names)
        meta[form] = {**data.meta, "scene": name, "beam": beam, "E_factor": e_factor}
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays, meta=np.array(json.dumps(meta)))
    path = atomic_write_bytes(HERE / "forms_exudyn.npz", buf.getvalue())
    print(f"{path.name}: {', '.join(FORMS)}")
    return path


if __name__ == "__main__":
    for name in sys.argv[1:] or SCENES:
        make(name)
    if not sys.argv[1:]:
        make_cantilever()
        make_markers()
        make_forms()
