"""Corrupted copies of the lab excerpts, and a worker that runs ``casflex inverse`` on each (tests/test_lab_fuzz.py).

:func:`corrupt_text` and :func:`corrupt_c3d` make a seeded corrupted copy of a TRC / .mot or a C3D file with one
to three of the faults a lab file meets: cells that are not numbers, are empty, infinite or absurd; lines lost,
repeated or swapped; a file cut short; bytes that are not text; header fields that lie or are missing; labels
renamed; tabs turned into spaces; in a C3D, bytes of its header, parameters or data overwritten, samples made
NaN, infinite or huge, the file cut.

Run as a script, this module is the worker: it reads one case a line on stdin (JSON: the command's arguments
and where its output goes; ``"api": true``: the OpenSim reader's Python API on the model ``argv[1]`` instead),
runs ``casflex.cli.main`` on it in this one process (CasADi and numpy loaded once) and writes one result a line
on stdout (JSON: the exit status, what stderr said, whether every load or scene number written is finite, or the
traceback of an exception that escaped). :func:`run_all` feeds it the cases and watches for hangs.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import struct
import subprocess
import sys
import threading
import time
import traceback

import numpy as np

BAD_CELLS = ("NaN", "nan", "", "inf", "-inf", "1e300", "-1e300", "abc", "0", "1e9", "-0", "1,5", "0x10", " ")


def _cell_lines(lines: list[str]) -> list[int]:
    """Indices of the data lines (after the header) that hold tab-separated cells."""
    start = next((i + 2 for i, ln in enumerate(lines) if ln.strip().lower() == "endheader"), 5)
    return [i for i in range(start, len(lines)) if "\t" in lines[i]]


def _text_fault(lines: list[str], rng: np.random.Generator) -> list[str]:
    if not lines:
        return lines
    data = _cell_lines(lines)
    kind = int(rng.integers(10))
    if kind <= 2 and data:  # a cell
        i = int(rng.choice(data))
        cells = lines[i].split("\t")
        cells[int(rng.integers(len(cells)))] = str(rng.choice(BAD_CELLS))
        lines[i] = "\t".join(cells)
    elif kind == 3 and data:  # a line lost
        del lines[int(rng.choice(data))]
    elif kind == 4 and data:  # a line repeated, or two swapped
        i, j = (int(v) for v in rng.choice(data, 2))
        lines.insert(i, lines[i]) if rng.random() < 0.5 else lines.__setitem__(slice(None), _swap(lines, i, j))
    elif kind == 5:  # a header line: a field changed or lost
        i = int(rng.integers(min(6, len(lines))))
        cells = lines[i].split("\t")
        cells[int(rng.integers(len(cells)))] = str(rng.choice(("", "0", "m", "cm", "-1", "sixty", "yes", "true", "x")))
        lines[i] = "\t".join(cells) if rng.random() < 0.8 else ""
    elif kind == 6 and data:  # tabs become spaces on one line
        i = int(rng.choice(data))
        lines[i] = lines[i].replace("\t", " ")
    elif kind == 7 and data:  # a column lost on one line
        i = int(rng.choice(data))
        cells = lines[i].split("\t")
        del cells[int(rng.integers(len(cells)))]
        lines[i] = "\t".join(cells)
    elif kind == 8:  # the times shifted or scaled, or one time changed
        data = data or [len(lines) - 1]
        col = 1 if len(lines[data[0]].split("\t")) > 20 else 0
        scale = float(rng.choice((1.0, 1.0, 2.0, -1.0)))
        shift = float(rng.choice((0.0, 0.05, 5.0, -1.0)))
        for i in data if rng.random() < 0.5 else [int(rng.choice(data))]:
            cells = lines[i].split("\t")
            try:
                cells[col] = f"{float(cells[col]) * scale + shift:.6f}"
            except (ValueError, IndexError):
                continue
            lines[i] = "\t".join(cells)
    elif data:  # many cells of one column: a marker or a channel gone for a while
        col = int(rng.integers(1, len(lines[data[0]].split("\t"))))
        start = int(rng.integers(len(data)))
        for i in data[start:start + int(rng.integers(1, 12))]:
            cells = lines[i].split("\t")
            if col < len(cells):
                cells[col] = str(rng.choice(("", "NaN", "0")))
                lines[i] = "\t".join(cells)
    return lines


def _swap(lines: list[str], i: int, j: int) -> list[str]:
    out = list(lines)
    out[i], out[j] = out[j], out[i]
    return out


def corrupt_text(text: str, seed: int) -> bytes:
    """A corrupted copy of a TRC or .mot file's text (module docstring), as bytes."""
    rng = np.random.default_rng(seed)
    lines = text.splitlines()
    for _ in range(int(rng.integers(1, 4))):
        lines = _text_fault(lines, rng)
    raw = ("\n".join(lines) + "\n").encode("utf-8")
    if rng.random() < 0.08 and raw:  # cut short
        raw = raw[:int(rng.integers(len(raw)))]
    if rng.random() < 0.05:  # bytes that are not text
        k = int(rng.integers(len(raw) + 1))
        raw = raw[:k] + bytes(rng.integers(128, 256, 4).tolist()) + raw[k:]
    return raw


def corrupt_c3d(raw: bytes, seed: int, parameters_end: int = 6656) -> bytes:
    """A corrupted copy of a C3D file (module docstring); ``parameters_end``: where its data section starts."""
    rng = np.random.default_rng(seed)
    b = bytearray(raw)
    for _ in range(int(rng.integers(1, 4))):
        kind = int(rng.integers(6))
        if kind == 0 and len(b) >= 512:  # bytes of the header
            i = int(rng.integers(512))
            b[i] = int(rng.integers(256))
        elif kind == 1 and len(b) >= parameters_end:  # bytes of the parameter section
            i = int(rng.integers(512, parameters_end))
            b[i:i + 2] = bytes(rng.integers(256, size=2).tolist())
        elif kind == 2 and len(b) > parameters_end + 4:  # a float sample of the data section: NaN, infinite, huge, zero
            i = parameters_end + 4 * int(rng.integers((len(b) - parameters_end) // 4))
            b[i:i + 4] = struct.pack("<f", float(rng.choice((np.nan, np.inf, -np.inf, 3e38, 0.0, 1e6))))
        elif kind == 3 and len(b) > parameters_end + 4:  # a run of samples of the data section
            i = parameters_end + 4 * int(rng.integers((len(b) - parameters_end) // 4))
            b[i:i + 4 * 32] = struct.pack("<f", np.nan) * 32
        elif kind == 4 and b:  # cut short
            b = b[:int(rng.integers(len(b)))]
        elif b:  # random bytes anywhere
            i = int(rng.integers(len(b)))
            b[i:i + 8] = bytes(rng.integers(256, size=8).tolist())
    return bytes(b)


def _finite_loads(path: str) -> bool | None:
    """Whether every load in the npz written at ``path`` is finite (None: no file)."""
    try:
        with np.load(path) as z:
            return bool(np.isfinite(z["loads"]).all() and np.isfinite(z["z"]).all())
    except FileNotFoundError:
        return None


def _finite_text(path: str) -> bool | None:
    """Whether the text file at ``path`` (a scene TOML) holds no NaN or infinity (None: no file)."""
    try:
        text = open(path, encoding="utf-8").read().lower()
    except FileNotFoundError:
        return None
    return not re.search(r"\b(nan|inf)\b", text)


def run_case(argv: list[str], out: str) -> dict:
    """``casflex.cli.main(argv)`` in this process: its exit status, stderr's lines, and whether what it wrote
    (loads, a scene) is finite."""
    from casflex.cli import main

    err = io.StringIO()
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            code = main(argv)
    except BaseException:  # noqa: BLE001 - a traceback is what the fuzz test looks for
        return {"code": None, "traceback": traceback.format_exc(limit=-4)}
    lines = [ln for ln in err.getvalue().splitlines() if ln.strip()]
    finite = (_finite_text(out) if out.endswith(".toml") else _finite_loads(out)) if code == 0 else None
    return {"code": code, "stderr": lines, "finite": finite}


def run_api(model: str) -> dict:
    """The OpenSim reader's Python API on ``model`` (``scene_from_osim``, then the scene assembled): exit status 0
    and whether every number of the scene is finite, or 2 and the ValueError's line, or the traceback."""
    from casflex.model import assemble
    from casflex.scene.from_osim import scene_from_osim
    from casflex.scene.io import dumps_scene

    try:
        made = scene_from_osim(model)
        assemble(made.scene)
    except ValueError as exc:
        return {"code": 2, "stderr": [f"casflex: error: {exc}"], "finite": None}
    except BaseException:  # noqa: BLE001 - a traceback is what the fuzz test looks for
        return {"code": None, "traceback": traceback.format_exc(limit=-4)}
    text = dumps_scene(made.scene).lower() + "\n".join(made.report).lower()
    return {"code": 0, "stderr": [], "finite": not re.search(r"\b(nan|inf)\b", text)}


def run_all(cases: list[dict], hang: float, fail) -> list[dict]:
    """Each case's result from one worker process (this module); ``fail(message)`` (pytest.fail) names a case
    that hangs (more than ``hang`` s) or crashes the process."""
    worker = subprocess.Popen([sys.executable, __file__], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                              cwd=os.path.dirname(os.path.abspath(__file__)))
    results: list[dict] = []
    got = threading.Event()

    def read() -> None:
        for line in worker.stdout:
            results.append(json.loads(line))
            got.set()

    threading.Thread(target=read, daemon=True).start()
    try:
        for case in cases:
            got.clear()
            worker.stdin.write(json.dumps(case) + "\n")
            worker.stdin.flush()
            deadline = time.monotonic() + hang
            while not got.wait(0.2):
                if worker.poll() is not None:
                    got.wait(1.0)  # the reader may still be taking the last line
                    if not got.is_set():
                        fail(f"case {case['name']} ({' '.join(case['argv'])}) crashed the process (exit status "
                             f"{worker.returncode})")
                if time.monotonic() > deadline:
                    fail(f"case {case['name']} ({' '.join(case['argv'])}) did not finish in {hang:g} s")
    finally:
        worker.kill()
        worker.wait()
    return results


def _worker() -> None:
    for line in sys.stdin:
        case = json.loads(line)
        result = run_api(case["argv"][1]) if case.get("api") else run_case(case["argv"], case["out"])
        sys.stdout.write(json.dumps({"case": case["name"], **result}) + "\n")
        sys.stdout.flush()


if __name__ == "__main__":
    _worker()


def judge(cases: list[dict], results: list[dict], *, option_ok: bool = False) -> tuple[list[str], int, int]:
    """(problems, accepted, refused) of the fuzz ``results`` (:func:`run_all`) of ``cases``: a traceback, exit 0 with
    a non-finite answer or an error line, a refusal (exit 2) other than one ``casflex: error:`` line naming the case's
    file (or one of its ``also``, or an option where ``option_ok``), a refusal that left something in the case's
    output ``folder`` (its ``api`` cases excepted), any other exit status."""
    by_name = {c["name"]: c for c in cases}
    problems, accepted, refused = [], 0, 0
    for r in results:
        case = by_name[r["case"]]
        if r["code"] is None:
            problems.append(f"{r['case']}: traceback\n{r['traceback']}")
            continue
        errors = [ln for ln in r["stderr"] if not ln.startswith("casflex: warning: ")]
        if r["code"] == 0:
            accepted += 1
            if r["finite"] is not True or errors:
                problems.append(f"{r['case']}: exit 0 with finite={r['finite']}, stderr {errors}")
        elif r["code"] == 2:
            refused += 1
            if len(errors) != 1 or not errors[0].startswith("casflex: error: "):
                problems.append(f"{r['case']}: refused without one error line: {errors}")
            elif not (any(f in errors[0] for f in (case["file"], *case.get("also", ())))
                      or (option_ok and "--" in errors[0])):
                problems.append(f"{r['case']}: the refusal names neither the file nor an option: {errors[0]}")
            left = sorted(os.listdir(case["folder"])) if case.get("folder") and not case.get("api") else []
            if left:
                problems.append(f"{r['case']}: refused, but left {left} in the output folder")
        else:
            problems.append(f"{r['case']}: exit {r['code']}: {errors}")
    return problems, accepted, refused
