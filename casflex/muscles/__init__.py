"""Muscles on a lab's trial: what the muscles crossing each joint carry, and the force each joint then bears.

The data flow (docs/muscles.md):

1. the model's muscles, read with its .osim (:mod:`casflex.scene.muscles`: pure data);
2. their paths' lengths and moment arms along the lab's coordinates, exact by AD of the length
   (:mod:`casflex.muscles.path`);
3. their force-length-velocity curves, OpenSim's (:mod:`casflex.muscles.curves`);
4. the activations that carry the inverse dynamics' joint moments at least cost (static optimization,
   :mod:`casflex.muscles.static_optimization`);
5. the force and moment each joint bears: the net intersegmental load plus every muscle crossing it
   (:mod:`casflex.muscles.reaction`); a trial end to end: :mod:`casflex.muscles.analysis`;
6. each output's band, one standard deviation, from the muscles' uncertain properties, the anthropometry and the
   markers' noise, and beside it the spread between static optimization's criteria (:mod:`casflex.muscles.bands`).
"""
