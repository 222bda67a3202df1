"""Write rajagopal_planar_wraps.osim (README.md): Rajagopal's 2016 model made planar with five right-leg muscles,
four of them wrapping over a cylinder about the plane's normal.

Run from the repository's root: ``python tests/data/muscles/make_rajagopal_wraps.py <Rajagopal2016.osim>`` (the file
from opensim-org/opensim-models, ``Models/Rajagopal/Rajagopal2016.osim``).
"""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

sys.path.insert(0, "studies")
from _planar_osim import planar_osim  # noqa: E402

KEEP = ["pelvis_tilt", "pelvis_tx", "pelvis_ty", "hip_flexion_r", "knee_angle_r", "ankle_angle_r"]
MUSCLES = ("bfsh_r", "gasmed_r", "gaslat_r", "soleus_r", "recfem_r")
WRAPS = ("Gastroc_at_condyles_r", "BF_at_gastroc_r", "KnExt_at_fem_r")
DEST = Path(__file__).parent / "rajagopal_planar_wraps.osim"


def main(source: str) -> None:
    planar_osim(source, str(DEST), KEEP, "rajagopal_planar_wraps", muscles=True)
    tree = ET.parse(DEST)
    root = tree.getroot()
    objs = root.find("Model/ForceSet/objects")
    for el in [el for el in objs if el.get("name") not in MUSCLES]:
        objs.remove(el)
    for el in objs:  # the gastrocnemii's second wrap (a cylinder tilted off the normal) out
        ws = el.find("GeometryPath/PathWrapSet/objects")
        for pw in [pw for pw in (ws if ws is not None else []) if pw.findtext("wrap_object").strip()
                   in ("GasLat_at_shank_r", "GasMed_at_shank_r")]:
            ws.remove(pw)
    for b in root.iter("Body"):
        s = b.find("WrapObjectSet/objects")
        for w in list(s if s is not None else []):
            if w.get("name") == "KnExt_at_fem_r":  # tilted 4.6 deg off the normal: made normal
                w.find("xyz_body_rotation").text = "0 0 0"
            if w.get("name") not in WRAPS:
                s.remove(w)
    ET.indent(tree, space=" ")
    tree.write(DEST, encoding="UTF-8", xml_declaration=True)


if __name__ == "__main__":
    main(sys.argv[1])
