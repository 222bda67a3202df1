"""Writes tests/data/lab/hamner_static_excerpt.trc: the first 30 frames (0.5 s at 60 Hz) of the static
trial of OpenSim's Hamner pipeline (subject02_static.trc), the markers of the built-in hamner_leg and the
right knee's and ankle's, the numbers as in the source and the header's counts adjusted.

    python tests/hamner_static.py [PATH/TO/opensim-models]   (default: the git mirror, at commit 20a888b)
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

MIRROR = "/work/.mirror/opensim-org+opensim-models/repo"
SOURCE = "Pipelines/Hamner/subject02_static.trc"
OUT = Path(__file__).parent / "data" / "lab" / "hamner_static_excerpt.trc"
FRAMES = 30
EXTRA = ("R.Knee.Lat", "R.Knee.Med", "R.Ankle.Lat", "R.Ankle.Med")


def source_text(models: str) -> str:
    path = Path(models) / SOURCE
    if path.exists():
        return path.read_text()
    return subprocess.run(["git", "-C", models, "show", f"20a888b:{SOURCE}"], check=True, capture_output=True,
                          text=True).stdout


def main(models: str = MIRROR) -> None:
    import casflex

    keep_labels = [m.label for m in casflex.load_scene("hamner_leg").markers] + list(EXTRA)
    lines = source_text(models).splitlines()
    labels = lines[3].split("\t")[2::3]
    labels = [s.strip() for s in labels if s.strip()]
    cols = [labels.index(k) for k in keep_labels]
    rate = lines[2].split("\t")
    rate[2], rate[3] = str(FRAMES), str(len(cols))
    head = [f"PathFileType\t4\t(X/Y/Z)\t{OUT.name}", lines[1], "\t".join(rate),
            "Frame#\tTime\t" + "\t\t\t".join(keep_labels) + "\t\t",
            "\t\t" + "\t".join(f"{c}{i + 1}" for i in range(len(cols)) for c in "XYZ"), ""]
    rows = []
    for line in lines[6:6 + FRAMES]:
        cells = line.split("\t")
        rows.append("\t".join(cells[:2] + [cells[2 + 3 * c + k] for c in cols for k in range(3)]))
    OUT.write_text("\n".join(head + rows) + "\n")


if __name__ == "__main__":
    main(*sys.argv[1:])
