"""casflex.muscles.emg: a raw EMG's envelope (band-pass, rectify, low-pass 6 Hz, over its peak) at the trial's frames,
drawn beside the activations (``casflex muscles --emg``); bad EMG input refused in one line. The EMG here is made in
tmp_path: noise whose amplitude bursts at known times (no public trial at hand carries EMG in a table)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from casflex.cli import main
from casflex.lab.tables import write_sto
from casflex.muscles.emg import emg_envelopes

DATA = Path(__file__).parent / "data" / "muscles"
LAB = Path(__file__).parent / "data" / "lab"
MODEL = DATA / "hamner_subject02_planar_muscles.osim"
TRIAL = ["--data", str(LAB / "hamner_running_whole.trc"), "--loads", str(LAB / "hamner_running_whole_grf.mot"),
         "--plate", "calcn_r=ground_", "--plate", "calcn_l=1_ground_", "--tasks", str(LAB / "hamner_tasks_ik.xml"),
         "--cutoff", "10", "--t-end", "0.4"]


def _emg(tmp_path: Path, rate: float = 1000.0, t0: float = 0.0, t1: float = 1.5) -> Path:
    """SOL bursting at 0.3 s, TA at 0.9 s (Gaussian amplitudes of 50 ms SD on white noise, plus a 2 Hz drift the
    band-pass removes)."""
    rng = np.random.default_rng(47)
    t = np.arange(t0, t1 + 0.5 / rate, 1.0 / rate)
    burst = {"SOL": 0.3, "TA": 0.9}
    cols = {n: (0.05 + np.exp(-0.5 * ((t - c) / 0.05) ** 2)) * rng.standard_normal(t.size) + np.sin(4 * np.pi * t)
            for n, c in burst.items()}
    return write_sto(tmp_path / "emg.sto", t, cols, title="emg", units={n: "V" for n in cols})


def test_the_envelope_rises_where_the_muscle_fires(tmp_path):
    t = np.linspace(0.1, 1.2, 67)
    env = emg_envelopes(_emg(tmp_path), {"soleus_r": "SOL", "tib_ant_r": "TA"}, t)
    assert np.isclose(env["soleus_r"].max(), 1.0, atol=0.05) and np.isclose(env["tib_ant_r"].max(), 1.0, atol=0.05)
    assert abs(t[np.argmax(env["soleus_r"])] - 0.3) < 0.04  # the burst's time (within its 50 ms SD)
    assert abs(t[np.argmax(env["tib_ant_r"])] - 0.9) < 0.04
    assert env["soleus_r"][t > 0.6].max() < 0.2 and env["tib_ant_r"][t < 0.6].max() < 0.2  # off elsewhere


@pytest.mark.parametrize("columns, kwargs, message", [
    ({"soleus_r": "GAS"}, {}, "emg: .*emg.sto: column 'GAS' \\(for 'soleus_r'\\) is not in the file"),
    ({"sol_r": "SOL"}, {"muscles": ("soleus_r",)}, "muscle 'sol_r' is no muscle of the model"),
    ({"soleus_r": "SOL"}, {"rate": 60.0}, "sampled at 60 Hz: an envelope needs the raw EMG"),
    ({"soleus_r": "SOL"}, {"t1": 0.8}, "spans 0..0.8 s; the trial's window is 0.1..1.2 s"),
])
def test_bad_emg_is_refused_naming_the_file_and_column(tmp_path, columns, kwargs, message):
    muscles = kwargs.pop("muscles", ())
    with pytest.raises(ValueError, match=message):
        emg_envelopes(_emg(tmp_path, **kwargs), columns, np.linspace(0.1, 1.2, 67), muscles)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_an_emg_gap_is_refused_naming_it(tmp_path, bad):
    """A NaN gap (a channel lost for 50 ms) or one infinite sample: the filters ran through it and the envelope was
    all NaN, refused as "flat over the trial's window" (untrue) with numpy's RuntimeWarnings on stderr."""
    path = _emg(tmp_path)
    lines = path.read_text().splitlines()
    first = lines.index("endheader") + 2
    for i in range(first + 700, first + (750 if np.isnan(bad) else 701)):
        cells = lines[i].split("\t")
        cells[1] = str(bad)
        lines[i] = "\t".join(cells)
    path.write_text("\n".join(lines) + "\n")
    n = 50 if np.isnan(bad) else 1
    with pytest.raises(ValueError, match=rf"emg: .*emg.sto: column 'SOL' \(for 'soleus_r'\) has no number at {n} "
                                         r"samples \(t = 0.7\.\.0.7\d* s; NaN or infinite\); fill the gap"):
        emg_envelopes(path, {"soleus_r": "SOL"}, np.linspace(0.1, 1.2, 67))

def test_the_command_draws_the_emg_and_refuses_it_half_given(tmp_path, capsys):
    emg = str(_emg(tmp_path))
    out, plots = tmp_path / "out", tmp_path / "plots"
    assert main(["muscles", str(MODEL), *TRIAL, "--reserves", "1", "--joints", "hip_r", "--emg", emg,
                 "--emg-column", "soleus_r=SOL", "--emg-column", "tib_ant_r=TA", "--out", str(out),
                 "--plots", str(plots), "--quiet"]) == 0
    assert (plots / "activations.png").stat().st_size > 0
    capsys.readouterr()
    for argv, message in ((["--emg", emg], "--emg: give the EMG file"),
                          (["--emg", emg, "--emg-column", "soleus_r"], "--emg-column: expected MUSCLE=COLUMN"),
                          (["--emg", emg, "--emg-column", "soleus_r=XX", "--plots", str(tmp_path / "p2")],
                           "column 'XX' (for 'soleus_r') is not in the file")):
        o = tmp_path / "o2"
        plot_dir = [] if "--plots" in argv else ["--plots", str(tmp_path / "p3")]
        code = main(["muscles", str(MODEL), *TRIAL, "--reserves", "1", *argv, *plot_dir, "--out", str(o), "--quiet"])
        err = [ln for ln in capsys.readouterr().err.splitlines() if not ln.startswith("casflex: warning: ")]
        assert code == 2 and len(err) == 1 and message in err[0], err
        assert not o.exists() or not any(o.iterdir())


def test_a_c3d_files_analog_channel_is_read_by_its_label():
    """The walking2 excerpt's analog channels (its plates' raw signals at 2000 Hz, tests/data/lab/README.md) stand
    in for EMG: the channel named reaches the envelope, a label the file lacks is refused naming its labels."""
    c3d = LAB / "walking2_excerpt.c3d"
    t = np.linspace(2.6, 3.3, 43)
    env = emg_envelopes(c3d, {"soleus_r": "Fz1"}, t)["soleus_r"]
    assert env.shape == t.shape and np.isclose(env.max(), 1.0, atol=0.05) and env.min() >= -0.05
    with pytest.raises(ValueError, match=r"column 'EMG1' \(for 'soleus_r'\) is not in the file; its columns are "
                                         r"\['Fx1', 'Fy1'"):
        emg_envelopes(c3d, {"soleus_r": "EMG1"}, t)
