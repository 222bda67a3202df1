"""Shared small scene factories for the tests.

``cantilever`` and ``pendulum`` are plain functions (usable as ``from conftest import
cantilever`` under pytest's default import mode) and are also offered as the fixtures
``make_cantilever`` and ``make_pendulum`` that return the factory.
"""

from __future__ import annotations

import os

# The models in these tests are small (< 200 dofs): a multi-threaded BLAS only adds thread
# start-up and contention, which on a busy 2-core machine made a 100 x 100 solve take 0.1 s
# instead of 0.1 ms. Use one thread unless the caller chose otherwise. Effective only if numpy
# is not imported yet (pytest imports this conftest before the test modules).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import dataclasses  # noqa: E402
import math  # noqa: E402
import shutil  # noqa: E402
import tempfile  # noqa: E402

import pytest  # noqa: E402

from casflex import Beam, Load, Node, Scene, Support  # noqa: E402

#: The session's own compiled-code cache when CASFLEX_CACHE is unset (made by pytest_configure, removed by
#: pytest_unconfigure); None when the user's CASFLEX_CACHE is kept or a parent process made the directory.
_SESSION_CACHE: str | None = None


def pytest_configure(config) -> None:
    """Compiled libraries and built models go to a temporary CASFLEX_CACHE for the session unless the caller set one
    (as .ci/any-machine does, or to keep a cache across sessions): the tests never write to ~/.cache/casflex. Set
    here, before any test module is imported and before xdist starts its workers, which inherit it and so share one
    cache (the controller, which made it, removes it)."""
    global _SESSION_CACHE
    if os.environ.get("CASFLEX_CACHE"):
        return
    _SESSION_CACHE = tempfile.mkdtemp(prefix="casflex-test-cache-")
    os.environ["CASFLEX_CACHE"] = _SESSION_CACHE


def pytest_unconfigure(config) -> None:
    global _SESSION_CACHE
    if _SESSION_CACHE is not None:
        shutil.rmtree(_SESSION_CACHE, ignore_errors=True)
        os.environ.pop("CASFLEX_CACHE", None)
        _SESSION_CACHE = None


#: A steel-like default section (SI): E (Pa), A (m^2), I (m^4), rho (kg/m^3).
STEEL = {"E": 2.1e11, "A": 1e-4, "I": 1e-9, "rho": 7800.0}


def cantilever(
    n_elements: int = 8,
    L: float = 1.0,
    E: float = STEEL["E"],
    A: float = STEEL["A"],
    I: float = STEEL["I"],  # noqa: E741
    rho: float = STEEL["rho"],
    *,
    load: tuple[float, float, float] | None = None,
    gravity: tuple[float, float] = (0.0, 0.0),
    angle: float = 0.0,
    rotary_inertia: bool = False,
) -> Scene:
    """A beam clamped at node ``root`` (0, 0), free at node ``tip`` at distance L (m) in direction ``angle`` (rad).

    ``load = (fx, fy, mz)`` (N, N, N m) acts on the tip as load ``tipload``. The beam is called
    ``beam`` and meshed into ``n_elements`` equal elements (mesh nodes ``beam.1`` ...). No gravity
    unless given. Dof names: ``xtip``, ``ytip``, ``thetatip``, ...
    """
    loads = () if load is None else (Load("tipload", "tip", fx=load[0], fy=load[1], mz=load[2]),)
    tip = Node("tip", L * math.cos(angle), L * math.sin(angle), theta=angle)
    beam = Beam("beam", ("root", "tip"), E=E, A=A, I=I, rho=rho, elements=n_elements, rotary_inertia=rotary_inertia)
    return Scene(
        name="cantilever",
        nodes=(Node("root", 0.0, 0.0, theta=angle), tip),
        beams=(beam,),
        supports=(Support("clamp", "root", "clamp"),),
        loads=loads,
        gravity=gravity,
    )


def pendulum(
    n_elements: int = 4,
    L: float = 1.0,
    E: float = STEEL["E"],
    A: float = 1e-3,
    I: float = 1e-7,  # noqa: E741
    rho: float = STEEL["rho"],
    *,
    angle: float = 0.0,
    gravity: tuple[float, float] = (0.0, -9.81),
    load: tuple[float, float, float] | None = None,
) -> Scene:
    """A stiff rod pinned at node ``pivot`` (0, 0); free end ``end`` at ``angle`` (rad) from hanging straight down.

    The rod ``rod`` (meshed into ``n_elements``) starts straight and stress-free at
    (L sin angle, -L cos angle). Gravity acts, so the start is not an equilibrium (not even for
    angle = 0: the rod stretches). ``load = (fx, fy, mz)`` acts on ``end`` as load ``endload``.
    """
    th = angle - math.pi / 2  # chord direction
    loads = () if load is None else (Load("endload", "end", fx=load[0], fy=load[1], mz=load[2]),)
    return Scene(
        name="pendulum",
        nodes=(Node("pivot", 0.0, 0.0, theta=th), Node("end", L * math.sin(angle), -L * math.cos(angle), theta=th)),
        beams=(Beam("rod", ("pivot", "end"), E=E, A=A, I=I, rho=rho, elements=n_elements),),
        supports=(Support("pin", "pivot", "pin"),),
        loads=loads,
        gravity=gravity,
    )


def newmark_fd(r, q, qd, qdd, qa, c, alpha: float, e: float = 1e-6):
    """Central differences of r(q, qd, qdd, qa) along the Newmark relations (dqd/dq = c[0],
    dqdd/dq = c[1], dqa/dq = 1 + alpha): the columns of an element's HHT tangent K = dr/dq.
    Truncation ~e^2 times the third derivative, round-off eps |r| / e ~ 1e-10 |K| at e = 1e-6."""
    import numpy as np

    def at(d):
        return np.array(r(q + d, qd + c[0] * d, qdd + c[1] * d, qa + (1 + alpha) * d)).ravel()

    return np.column_stack([(at(e * ei) - at(-e * ei)) / (2 * e) for ei in np.eye(len(q))])


@pytest.fixture
def make_cantilever():
    """The :func:`cantilever` factory."""
    return cantilever


@pytest.fixture
def make_pendulum():
    """The :func:`pendulum` factory."""
    return pendulum


def translated(scene: Scene, dx: float) -> Scene:
    """``scene`` with every node moved by dx (m) along x: physically the same, numerically far off."""
    return dataclasses.replace(scene, nodes=tuple(dataclasses.replace(n, x=n.x + dx) for n in scene.nodes))


def twobar_meshed(elements: int) -> Scene:
    """The built-in twobar scene with ``elements`` elements per bar."""
    import casflex

    scene = casflex.load_scene("twobar")
    return dataclasses.replace(scene, beams=tuple(dataclasses.replace(b, elements=elements) for b in scene.beams))


#: The modules with the longest tests (10-45 s each; the profiles of 2026-11-28/29), longest first. They run first:
#: pytest-xdist hands the tests out in collection order and keeps two queued on a worker to the end, so a long test
#: collected last (test_study_muscles, test_sweep: 15-30 s) ran while the other worker had nothing left, and the
#: run's end waited on it. Only the order of whole modules changes (their module-scoped fixtures are made once).
LONG_FIRST = ("test_leg_scene", "test_cli_interrupt", "test_study_muscles", "test_dampers",
              "test_identification_priors", "test_cli_identify", "test_studies", "test_study",
              "test_identification_realdata", "test_identification_indirect", "test_study_cluster", "test_sweep",
              "test_identification_markers", "test_identification_adapted", "test_identification_form")


def pytest_collection_modifyitems(items: list) -> None:
    """The modules of :data:`LONG_FIRST` before the others (each module's tests in their order)."""
    rank = {f"tests/{name}.py": k for k, name in enumerate(LONG_FIRST)}

    def key(item) -> int:
        return rank.get(item.nodeid.split("::")[0], len(rank))

    items.sort(key=key)  # stable: the other modules keep pytest's order


def pytest_terminal_summary(terminalreporter) -> None:
    """The versions this run was made with (shown also under -q): a failure report is
    reproducible only with them."""
    import platform
    from importlib.metadata import PackageNotFoundError, version

    found = []
    for pkg in ("casflex", "casadi", "numpy", "scipy", "matplotlib", "distributed"):
        try:
            found.append(f"{pkg} {version(pkg)}")
        except PackageNotFoundError:
            found.append(f"{pkg} (not installed)")
    terminalreporter.write_line(f"versions: Python {platform.python_version()}, " + ", ".join(found))


def assert_same_numbers(a, b) -> None:
    """Arrays of an interpreted and a compiled run of the same steps: bitwise where casflex promises it
    (:func:`casflex.codegen.bitwise_expected`: x86-64 with the default flags). Under other
    CASFLEX_CFLAGS the promise is per step (tests/test_codegen.py); here to 1e-9 of the largest value:
    -march=native on an AVX-512 Xeon left 3e-15 m after 300 steps of twobar, a margin of 1e5 for these
    short runs (<= 2,500 steps)."""
    import numpy as np

    from casflex import codegen

    a, b = np.asarray(a), np.asarray(b)
    if codegen.bitwise_expected():
        np.testing.assert_array_equal(a, b)
    else:
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * max(np.abs(a).max(), 1e-300))


def assert_scenes_close(a, b, rel: float, *, path: str = "scene") -> None:
    """``a == b`` for scenes or their items (frozen dataclasses, tuples of them), with floats equal to
    ``rel`` relative instead of bit for bit; strings, ints, bools, None and the structure (types, lengths)
    exactly. For a built-in scene file written on one machine against the same scene recomputed here
    (tests/hamner_leg.py, leg_rigid.py, slidercrank.py): another CPU's libm and BLAS differ in the last
    digits. Each caller states where its ``rel`` comes from. Raises at the first difference, naming it."""
    import dataclasses

    if isinstance(a, float) or isinstance(b, float):
        numbers = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (a, b))
        assert numbers and math.isclose(a, b, rel_tol=rel, abs_tol=0.0), f"{path}: {a!r} != {b!r} (relative {rel:g})"
    elif dataclasses.is_dataclass(a) and not isinstance(a, type):
        assert type(a) is type(b), f"{path}: {type(a).__name__} != {type(b).__name__}"
        name = getattr(a, "name", None)
        where = f"{path}({name})" if isinstance(name, str) and path != "scene" else path
        for f in dataclasses.fields(a):
            assert_scenes_close(getattr(a, f.name), getattr(b, f.name), rel, path=f"{where}.{f.name}")
    elif isinstance(a, (tuple, list)):
        assert type(a) is type(b), f"{path}: {type(a).__name__} != {type(b).__name__}"
        assert len(a) == len(b), f"{path}: {len(a)} items != {len(b)}"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_scenes_close(x, y, rel, path=f"{path}[{i}]")
    else:
        assert a == b, f"{path}: {a!r} != {b!r}"
