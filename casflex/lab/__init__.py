"""The motion lab's files, in SI and named: markers (TRC, C3D), tables (OpenSim's .mot / .sto, C3D force plates),
the plane that takes the lab's axes to a scene's, the labs' filters, and the limits no body in a lab reaches.

- :mod:`casflex.lab.tables`: :func:`read_trc`, :func:`write_trc`, :func:`read_sto` (:class:`LabMarkers`,
  :class:`LabTable`);
- :mod:`casflex.lab.c3d`: :func:`read_c3d`, a C3D file's markers and force plates (through the optional ezc3d);
- :mod:`casflex.lab.plane`: :class:`Plane`, :func:`markers_in_plane`, :func:`trial_markers`;
- :mod:`casflex.lab.filtering`: :func:`filtered` (the zero-lag Butterworth on markers and tables), force plates
  as force and moment about the origin (:func:`plate_wrench`, :func:`plate_moment_about_origin`,
  :func:`centre_of_pressure`);
- :mod:`casflex.lab.lowpass`: the one Butterworth implementation every caller uses, evenly spaced times;
- :mod:`casflex.lab.checks`: what no body produces (corrupted files refused in one line).

Data flow one way: files -> these readers -> named tables in SI -> the scene's inputs (:mod:`casflex.scene.files`),
inverse dynamics (:mod:`casflex.inverse`), identification's measurement sets.
"""

from casflex.lab.c3d import read_c3d
from casflex.lab.filtering import centre_of_pressure, filtered, plate_moment_about_origin, plate_wrench
from casflex.lab.plane import Plane, markers_in_plane, trial_markers
from casflex.lab.tables import UNITS, LabMarkers, LabTable, increasing_times, read_sto, read_trc, write_trc

__all__ = ["LabMarkers", "LabTable", "Plane", "UNITS", "read_trc", "write_trc", "read_sto", "increasing_times",
           "read_c3d", "markers_in_plane", "trial_markers", "filtered", "plate_moment_about_origin", "plate_wrench",
           "centre_of_pressure"]
