"""The marker fit on every frame at once (casflex/inverse/frames.py) against the frame-by-frame fit it replaces in
fit_markers: the same poses, residuals and decisions on the Hamner run with its task weights, missing markers, a
coordinate held at a limit and the fall-back to frame by frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from casflex.inverse import fit as fit_module
from casflex.inverse import inverse_model, kinematic_tree
from casflex.inverse.fit import (
    _kabsch_start,
    _levenberg_marquardt,
    _MarkerFit,
    coordinate_bounds,
    fit_markers,
    marker_weights,
)
from casflex.inverse.frames import MappedFit, kabsch_starts, levenberg_marquardt

LAB = Path(__file__).parent / "data" / "lab"
#: rad, m: the frame-by-frame fit's own spread: its poses move by 1e-8 when its starts move by 1e-9 (steps below
#: ~1e-8 no longer change the sum of squares in double precision, and its stop at 1e-10 falls among them)
SPREAD = 1e-7


@pytest.fixture(scope="module")
def trial():
    from casflex.inverse.inputs import weighted
    from casflex.lab import read_trc
    from casflex.scene.from_osim import scene_from_osim

    scene = weighted(scene_from_osim(LAB / "hamner_subject02_planar.osim").scene, LAB / "hamner_tasks_ik.xml")[0]
    tree = kinematic_tree(inverse_model(scene))
    trc = read_trc(LAB / "hamner_running_whole.trc")
    y = np.concatenate([trc.marker(m.label)[:, :2] for m in tree.model.scene.markers], axis=1)
    return tree, trc.t, y


def _frame_by_frame(tree, y, bounds="model"):
    """The fit as it ran before, each frame from the last one decided (the reference)."""
    f, w = _MarkerFit(tree.marker_fit), marker_weights(tree)
    bounds = coordinate_bounds(tree) if bounds == "model" else bounds
    y0 = f(tree.coordinates(tree.model.q0))[0].copy()
    Z, ok, z_prev = np.full((y.shape[0], tree.n), np.nan), np.zeros(y.shape[0], bool), None
    for i in range(y.shape[0]):
        start = _kabsch_start(tree, y[i], y0) if z_prev is None else z_prev
        z, _, ok[i] = _levenberg_marquardt(f, start, y[i], 50, w, bounds)
        if ok[i]:
            Z[i] = z_prev = z
    return Z, ok


def test_the_mapped_evaluation_gives_each_frame_s_numbers(trial):
    tree, _, _ = trial
    Z = np.random.default_rng(1).normal(0.0, 0.5, (13, tree.n))  # 8 + 5 x 1: two of the chunk sizes
    Y, J = MappedFit(tree.marker_fit)(Z)
    one = _MarkerFit(tree.marker_fit)
    for k in range(13):
        y, Jk = one(Z[k])
        assert np.array_equal(Y[k], y) and np.array_equal(J[k], Jk)


def test_the_rigid_starts_are_each_frame_s(trial):
    tree, _, y = trial
    y = y.copy()
    y[5, :6] = np.nan  # a frame missing markers: each segment's fit from those it has
    y0 = _MarkerFit(tree.marker_fit)(tree.coordinates(tree.model.q0))[0].copy()
    starts = kabsch_starts(tree, y, y0)
    for i in (0, 5, 30):
        np.testing.assert_allclose(starts[i], _kabsch_start(tree, y[i], y0), rtol=0, atol=1e-12)  # the same sums


def test_all_frames_at_once_end_where_frame_by_frame_does(trial):
    tree, t, y = trial
    want, ok = _frame_by_frame(tree, y)
    got = fit_markers(tree, t, y, max_misfit=0.3)
    assert ok.all() and np.isfinite(got.z).all()
    assert np.abs(got.z - want).max() < SPREAD
    f, w = _MarkerFit(tree.marker_fit), marker_weights(tree)
    r = [_levenberg_marquardt(f, want[i], y[i], 50, w, coordinate_bounds(tree))[1] for i in (0, 40)]
    rms = [float(np.sqrt(np.mean(ri.reshape(-1, 2) ** 2, axis=0).sum())) for ri in r]
    np.testing.assert_allclose(got.rms[[0, 40]], rms, rtol=0, atol=SPREAD)


def test_a_frame_without_markers_is_a_gap_and_the_next_starts_from_the_last_decided(trial):
    tree, t, y = trial
    y = y.copy()
    y[20:22] = np.nan  # two frames see nothing: gaps, filled by the spline
    want, ok = _frame_by_frame(tree, y)
    got = fit_markers(tree, t, y, max_misfit=0.3)
    assert not ok[20:22].any() and np.isnan(got.rms[20:22]).all()
    assert np.abs(got.z[ok] - want[ok]).max() < SPREAD
    assert any(line.startswith("gaps: 2 frames") for line in got.report)


def test_a_coordinate_held_at_a_limit_is_held_there_as_frame_by_frame(trial):
    tree, _, y = trial
    lo, hi = coordinate_bounds(tree)
    free, _ = _frame_by_frame(tree, y[:12])
    k = tree.names.index("knee_r.angle")
    hi = hi.copy()
    hi[k] = np.median(free[:, k])  # below the free optimum in about half the frames
    want, _ = _frame_by_frame(tree, y[:12], (lo, hi))
    Z, _, decided = levenberg_marquardt(MappedFit(tree.marker_fit), want + 1e-3, y[:12], marker_weights(tree), lo, hi)
    assert decided.all() and (Z[:, k] <= hi[k]).all() and (Z[:, k] == hi[k]).sum() >= 5
    assert np.abs(Z - want).max() < SPREAD


def test_starts_that_do_not_agree_fall_back_to_frame_by_frame(trial, monkeypatch):
    tree, t, y = trial
    monkeypatch.setattr(fit_module, "_AGREE", -1.0)  # every first-pass pose "apart": frame by frame after the first
    calls = []
    one_by_one = fit_module._one_by_one
    monkeypatch.setattr(fit_module, "_one_by_one", lambda *a: calls.append(a[-1]) or one_by_one(*a))
    want, _ = _frame_by_frame(tree, y[:15])
    got = fit_markers(tree, t[:15], y[:15])
    assert calls == [1] and np.abs(got.z - want).max() < SPREAD
    f, w = _MarkerFit(tree.marker_fit), marker_weights(tree)
    second = _levenberg_marquardt(f, got.z[0], y[1], 50, w, coordinate_bounds(tree))[0]
    assert np.array_equal(got.z[1], second)  # frame 1 fitted alone, from frame 0's pose


def test_a_trial_longer_than_a_block_is_fitted_block_by_block_alike(trial, monkeypatch):
    tree, t, y = trial
    whole = fit_markers(tree, t, y)
    monkeypatch.setattr(fit_module, "_BLOCK", 16)  # 61 frames: four blocks, the last one short
    assert np.abs(fit_markers(tree, t, y).z - whole.z).max() < SPREAD
