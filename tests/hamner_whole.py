"""The whole-body planar model of Hamner subject 02 and an excerpt of the running trial with all its markers
and both plates, for tests/test_peers_opensim_tools.py (casflex against OpenSim's IK and ID tools).
``python tests/hamner_whole.py [MODELS]`` writes, from opensim-org/opensim-models at commit 20a888b (Apache
License 2.0; MODELS: a git directory or clone of it, default /work/.mirror/opensim-org+opensim-models/repo):

- tests/data/lab/hamner_subject02_planar.osim: outputReference/subject02_registered.osim made planar by
  studies/_planar_osim.py with the 14 coordinates of studies/opensim_gait.py free (what it changes: its
  docstring; the list is printed);
- tests/data/lab/hamner_running_whole.trc: subject02_running.trc's frames from T0 to T1 s, all 41 markers,
  rows as in the source, the header's frame count adjusted;
- tests/data/lab/hamner_running_whole_grf.mot: subject02_running_grf.mot's same rows, the time and both
  plates' 18 columns, numbers as in the source, the header rewritten;
- tests/data/lab/hamner_tasks_ik.xml: Pipelines/Hamner/Tasks_IK.xml as it is (the lab's IK weights).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "studies"))
sys.path.insert(0, str(HERE))

from _planar_osim import planar_osim  # noqa: E402
from hamner_leg import COMMIT, source_text  # noqa: E402
from opensim_gait import KEEP  # noqa: E402

LAB = HERE / "data" / "lab"
OSIM, TRC, GRF, TASKS = (LAB / "hamner_subject02_planar.osim", LAB / "hamner_running_whole.trc",
                         LAB / "hamner_running_whole_grf.mot", LAB / "hamner_tasks_ik.xml")
T0, T1 = 0.2, 1.2  # s: the right stance 0.40-0.65 s and the left 0.77-1.00 s inside, with margins
SRC = "Pipelines/Hamner/"


def _rows(text: str, t_col: int, skip: int) -> tuple[list[str], list[str]]:
    lines = text.splitlines()
    head, rows = lines[:skip], [ln for ln in lines[skip:] if ln.strip()]
    take = [r for r in rows if T0 - 1e-6 <= float(r.split("\t")[t_col]) <= T1 + 1e-6]
    return head, take


def main(models: str) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "subject02_registered.osim"
        src.write_text(source_text(models, SRC + "outputReference/subject02_registered.osim"), encoding="utf-8")
        changes = planar_osim(str(src), str(OSIM), KEEP, "subject02_planar")
    print("\n".join(changes))
    head, take = _rows(source_text(models, SRC + "subject02_running.trc"), 1, 6)
    keys, vals = head[1].rstrip("\t").split("\t"), head[2].rstrip("\t").split("\t")
    head[2] = "\t".join(str(len(take)) if k == "NumFrames" else v for k, v in zip(keys, vals, strict=False))
    TRC.write_text("\n".join([ln.rstrip("\t") for ln in head] + take) + "\n", encoding="utf-8")
    grf_text = source_text(models, SRC + "subject02_running_grf.mot")
    lines = grf_text.splitlines()
    end = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader")
    names = [n.strip() for n in lines[end + 1].split("\t")]
    keep = [0] + [i for i, n in enumerate(names) if n.startswith(("ground_", "1_ground_"))]
    _, take = _rows(grf_text, 0, end + 2)
    rows = ["\t".join(r.split("\t")[k].strip() for k in keep) for r in take]
    GRF.write_text("\n".join([f"name {GRF.name}", f"datacolumns {len(keep)}", f"datarows {len(rows)}",
                              f"range {float(rows[0].split()[0]):.6f} {float(rows[-1].split()[0]):.6f}", "endheader",
                              "\t".join(names[k] for k in keep), *rows]) + "\n", encoding="utf-8")
    TASKS.write_text(source_text(models, SRC + "Tasks_IK.xml"), encoding="utf-8")
    print(f"wrote {OSIM.name}, {TRC.name} ({len(take)} frames), {GRF.name}, {TASKS.name}; commit {COMMIT}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "/work/.mirror/opensim-org+opensim-models/repo")
