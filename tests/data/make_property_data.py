"""Writes ``twobar_properties_exudyn.npz`` and ``knee_pendulum_properties_exudyn.npz``: built-in scenes simulated
by another code with property values other than the scene's, within an uncertainty a scene would declare for
them (issue 37).

    python tests/data/make_property_data.py        # needs Exudyn: pip install -e '.[peers]'

Each variant (``VARIANTS``: both bars 5 % denser; bar 2 alone 5 % denser; both bars' E 3 % lower; all of these
together) is simulated by Exudyn (:mod:`casflex.peers.exudyn`: ANCF cable elements, 8 per beam, h = 1e-4 s,
Newton increments to 1e-10) over 0-3 s, and the positions of nodes 3 and 5 (the seed paper's measured channels)
are kept at 100 Hz, without noise (the tests and ``studies/uncertain.py`` add their own): keys ``t``,
``channels``, ``q_<variant>`` (m, (301, 4)) and ``meta`` (the properties of each variant, the code and its own
error against 16 elements per beam and h = 5e-5 s).

The knee pendulum's variants (``KNEE_VARIANTS``: the shank-foot's mass 10 % above Winter's table, its inertia
20 % below, and both 10 % and 20 % above) are written by the Exudyn model of
:func:`make_reference_data.make_knee_pendulum` (a rigid body on a revolute joint, the knee a coordinate
spring-damper; h = 1e-4 s), its five markers at 100 Hz over 5 s without noise: keys ``t``, ``channels``,
``q_<variant>`` (m, (501, 10)) and ``meta`` (the variants' properties, the code, the largest own error
against h = 5e-5 s).
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
CHANNELS = ("x3", "y3", "x5", "y5")
T_END, EVERY = 3.0, 10  # s; samples kept every EVERY ms
VARIANTS = {
    "heavy": {"bar2.rho": 1.05, "bar4.rho": 1.05},
    "heavy_bar2": {"bar2.rho": 1.05},
    "soft": {"bar2.E": 0.97, "bar4.E": 0.97},
    "all": {"bar2.rho": 1.05, "bar4.rho": 1.05, "bar2.E": 0.97, "bar4.E": 0.97},
}

KNEE_VARIANTS = {
    "mass": {"shank_foot.mass": 1.10},
    "inertia": {"shank_foot.inertia": 0.80},
    "both": {"shank_foot.mass": 1.10, "shank_foot.inertia": 1.20},
}


def make_knee() -> Path:
    import exudyn as exu
    from make_reference_data import KNEE, _knee_run

    import casflex
    from casflex.results import atomic_write_bytes

    base = casflex.load_scene("knee_pendulum")
    out, meta = {}, {"variants": {}, "error_xy": 0.0, "code": f"Exudyn {exu.__version__}", "h": KNEE["h"]}
    for name, factors in KNEE_VARIANTS.items():
        scene = base
        for target, f in factors.items():
            scene = scene.with_property(target, f * base.property_value(target))
        t, channels, q, _ = _knee_run(scene, KNEE["h"])
        _, _, q_fine, _ = _knee_run(scene, KNEE["h"] / 2)
        out[f"q_{name}"] = q
        meta["error_xy"] = max(meta["error_xy"], float(np.abs(q_fine - q).max()))
        meta["variants"][name] = {tg: scene.property_value(tg) for tg in factors}
    buf = io.BytesIO()
    np.savez_compressed(buf, t=t, channels=np.array(channels), **out,
                        meta=np.array(json.dumps({**meta, "check": "against h = 5e-5 s"})))
    path = atomic_write_bytes(HERE / "knee_pendulum_properties_exudyn.npz", buf.getvalue())
    print(f"{path.name}: {len(KNEE_VARIANTS)} variants, own error {meta['error_xy']:.2e} m, {meta['code']}")
    return path


def make() -> Path:
    import casflex
    from casflex.peers import exudyn
    from casflex.results import atomic_write_bytes

    base = casflex.load_scene("twobar")
    out, meta = {}, {"variants": {}, "error_xy": 0.0}
    for name, factors in VARIANTS.items():
        scene = base
        for target, f in factors.items():
            scene = scene.with_property(target, f * base.property_value(target))
        data = exudyn.simulate(scene, T_END, elements=8, h=1e-4, sample_dt=1e-3)
        fine = exudyn.simulate(scene, T_END, elements=16, h=5e-5, sample_dt=1e-3, newton_tol=1e-9)
        cols = [list(data.channels).index(c) for c in CHANNELS]
        out[f"q_{name}"] = data.q[::EVERY, cols]
        meta["error_xy"] = max(meta["error_xy"], float(np.abs(fine.q[::EVERY, cols] - out[f"q_{name}"]).max()))
        meta["variants"][name] = {t: scene.property_value(t) for t in factors}
        meta.update(code=data.meta["code"], t=data.t[::EVERY].tolist())
    buf = io.BytesIO()
    np.savez_compressed(buf, t=np.array(meta.pop("t")), channels=np.array(CHANNELS), **out,
                        meta=np.array(json.dumps({**meta, "check": "against 16 elements per beam, h = 5e-5 s"})))
    path = atomic_write_bytes(HERE / "twobar_properties_exudyn.npz", buf.getvalue())
    print(f"{path.name}: {len(VARIANTS)} variants, own error {meta['error_xy']:.2e} m, {meta['code']}")
    return path


if __name__ == "__main__":
    import sys

    sys.path.insert(0, str(HERE))
    make()
    make_knee()
