"""A muscle's strength against its body's weight: a max isometric force no body's muscle has is refused, one a
human muscle does not reach is said.

The weight W (N) a muscle is measured against is the model's (its total mass x g) or, where the trial's plates
carry more (a model of part of the body: a leg's 25 kg of a 72 kg subject), a third of their largest total force
(a stance peaks at 1-3 body weights): never more than the subject's weight, but in landings. Measured, a model's
strongest muscle over its weight (OpenSim's models, opensim-models 20a888b): Hamner's 92 muscles 4.8 (generic,
75 kg) and 5.5 (subject 02, 66 kg; soleus 3549 N), gait2392 4.8, gait2354 6.8 (vasti 5000 N), gait10dof18musc 7.0
(soleus 5137 N), Rajagopal 2016 8.4 (soleus 6195 N on 75 kg; 7.4 on the walk's 85 kg subject). Models of part of a
body against their own mass: leg6dof9musc 20.6 (25.5 kg), arm26 29.6 (BRA 987 N on 3.4 kg). A model scaled to a
smaller subject keeps its forces (OpenSim's ScaleTool, :mod:`casflex.muscles.scaling`): Rajagopal's soleus on a
20 kg child, 32.

- :data:`STRONG` (x W): a muscle above 20 times the weight is said (on stderr and in the report), naming it, its
  force and the weight: 2.4 times Rajagopal's soleus, the strongest of the human models; a force typed ten times
  too large, or an adult's muscles on a child. Not refused: models of an arm or of a leg alone, or of a small
  subject, reach 20-30 against their own mass (and a small animal's muscles are stronger per weight: force goes
  with mass^(2/3)).
- :data:`ABSURD` (x W) and :data:`ABSURD_FORCE` (N): a muscle above 100 times the weight *and* above 20 kN is
  refused: no human muscle pulls 20 kN (the models' strongest 3.5-6.2 kN), and no animal's 100 times its weight
  (an elephant's largest muscles, some 1e5 N, pull 2-3 times its weight; a finger's flexor, 300 N on a 50 g
  finger, is below 20 kN). Such a force (3.5e8 N on Hamner's soleus_r: a unit or a typo) made static optimization
  give it the whole load, the ankle's reaction 7875 body weights and the reserves 3e5 % of its moment, exit 0.
"""

from __future__ import annotations

import math

__all__ = ["STRONG", "ABSURD", "ABSURD_FORCE", "check_strength"]

STRONG = 20.0
ABSURD = 100.0
ABSURD_FORCE = 2.0e4


def check_strength(muscles, weight: float, head: str = "", plates: float = 0.0) -> list[str]:
    """The lines that say a muscle of ``muscles`` (:class:`casflex.scene.muscles.Muscle`) is stronger than
    :data:`STRONG` times the weight (module docstring); ValueError in one line naming the muscle for one above
    :data:`ABSURD` times it and :data:`ABSURD_FORCE`, or whose force is not a finite number > 0. ``weight`` (N): the
    model's mass x g; ``plates`` (N): the trial's plates' largest total force (0: none); ``head``: the file, as
    messages name it (``model.osim: ForceSet: ``)."""
    w = max(weight, plates / 3.0)
    whose = "the model's weight" if w == weight else "a third of the plates' largest force"
    lines = []
    for m in muscles:
        f = m.max_isometric_force
        what = f"{head}{m.kind} {m.name!r}.max_isometric_force"
        if not (math.isfinite(f) and f > 0):
            raise ValueError(f"{what}: expected a finite force > 0 N, got {f!r}")
        if not w > 0:
            continue
        if f > ABSURD * w and f > ABSURD_FORCE:
            raise ValueError(f"{what}: {f:.4g} N, {f / w:.3g} times {whose} ({w:.0f} N): no muscle pulls more than "
                             f"{ABSURD:g} times its body's weight and {ABSURD_FORCE:g} N (a human's strongest 5-9 "
                             "body weights, some 6 kN): a typo or another unit; give the force in N")
        if f > STRONG * w:
            lines.append(f"{what}: {f:.4g} N, {f / w:.3g} times {whose} ({w:.0f} N); a human's strongest muscles "
                         f"pull 5-9 body weights in these models (above {STRONG:g}: a force typed too large, an "
                         "adult's muscles on a small subject, or a model of part of a body, whose weight is its "
                         "part's)")
    return lines
