"""The identification's option values, in a module light enough for the command line's parser
(importing the methods costs 0.7 s, paid by every ``casflex`` command that builds the parser)."""

#: Parameter transforms (problem.ParameterMap).
TRANSFORMS = ("linear", "log")
#: Hessians of the NLPs.
HESSIANS = ("exact", "gauss-newton")
#: The direct methods' beam forces: unknowns at each instant, or the model's.
BEAM_FORCES = ("unknown", "model")
#: Residues of the shooting NLPs.
RESIDUES = ("positions", "full")
#: Transcriptions of the indirect method.
TRANSCRIPTIONS = ("multiple-shooting", "single-shooting")
#: Initial states of an experiment.
INITIAL_STATES = ("scene", "velocities", "estimate")
#: What the indirect method does about the model's discretisation error.
MODEL_ERRORS = ("refine", "none")
#: Which alternative forms the indirect method compares: casflex's own too ("auto") or only the user's.
FORMS = ("auto", "none")
#: Losses of the indirect method's fit: least squares, or Huber's, robust to marker artefacts (by reweighting).
LOSSES = ("linear", "huber")
#: How the direct methods obtain velocities and accelerations from positions (:mod:`.smoothing`).
SMOOTHERS = ("spline", "butterworth")
#: casflex's own solver: single shooting by Gauss-Newton on forward sensitivities (the indirect method).
GAUSS_NEWTON = "gauss-newton"
#: The identification methods by name (the command line's --method).
METHODS = ("direct", "adapted-direct", "indirect")
