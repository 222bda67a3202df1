"""The NLP solver of :mod:`.shooting_nlp` on the interval Functions (:mod:`.shooting_intervals`).

With the Gauss-Newton Hessian the solver is handed every derivative it evaluates, all from the
mapped interval blocks (:meth:`.Transcription.gauss_newton`): ``grad_f``, ``jac_g``, ``hess_lag``
(f_scale J^T J, constraint curvature ignored) and, in a compiled library, ``nlp_grad`` (the
Lagrangian's gradient CasADi asks for after the solve). ``compiled``: the solver's functions and
the single-shooting residue are generated as ONE C library, compiled (gcc -O1) and cached on disk;
a later process finds it by the NLP's serialised Functions after the interpreted set-up (cheap:
CasADi derives nothing), by :func:`casflex.codegen.compiled_nlpsol` with ``nlp_grad`` replaced.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import casadi as ca

from casflex import codegen
from casflex.identification import problem as pb

__all__ = ["gauss_newton_nlpsol", "nlp_functions"]


def nlp_functions(gn: ca.Function, triu: bool) -> dict[str, ca.Function]:
    """The nlpsol option Functions of ``indirect_gn(w) -> (f, g, grad_f, jac_g, H)``: ``grad_f``,
    ``jac_g`` and ``hess_lag`` (lam_f H, H's upper triangle if ``triu``)."""
    x, p = ca.MX.sym("x", gn.size1_in(0)), ca.MX.sym("p", 0, 1)
    lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", gn.size1_out(1))
    f, g, gf, jg, H = gn(x)
    return {"grad_f": ca.Function("indirect_grad_f", [x, p], [f, gf], ["x", "p"], ["f", "grad_f_x"]),
            "jac_g": ca.Function("indirect_jac_g", [x, p], [g, jg], ["x", "p"], ["g", "jac_g_x"]),
            "hess_lag": ca.Function("indirect_hess_l", [x, p, lam_f, lam_g], [lam_f * H], ["x", "p", "lam_f", "lam_g"],
                                    ["triu_hess_gamma_x_x" if triu else "hess_gamma_x_x"])}


def _lagrangian_gradient(template: ca.Function, gn: ca.Function) -> ca.Function:
    """``nlp_grad`` as CasADi's ``template`` (x, p, lam_f, lam_g) -> (f, g, grad_gamma_x, grad_gamma_p),
    from ``indirect_gn``: lam_f grad_f + jac_g^T lam_g (no parameters p)."""
    x, p, lam_f, lam_g = template.mx_in()
    f, g, gf, jg, _ = gn(x)
    return ca.Function("nlp_grad", [x, p, lam_f, lam_g],
                       [f, g, lam_f * gf + ca.mtimes(jg.T, lam_g), ca.MX(template.sparsity_out(3))],
                       template.name_in(), template.name_out())


def _own_gradient(gn: ca.Function, fname: str, f: ca.Function) -> ca.Function:
    """The solver's Function ``fname`` to compile: ``nlp_grad`` from ``gn`` (CasADi's would differentiate
    the whole NLP), any other as it is."""
    return _lagrangian_gradient(f, gn) if fname == "nlp_grad" and f.n_in() == 4 and f.n_out() == 4 else f


def gauss_newton_nlpsol(name: str, solver: str, nlp: dict, gn_of: Callable[[bool], ca.Function], *,
                        compiled: bool, verbose: bool, solver_options: dict | None, tol: float,
                        extra: list[ca.Function]) -> tuple[ca.Function, dict[str, ca.Function]]:
    """``ca.nlpsol`` of ``nlp`` (x, f, g) with the derivatives of ``gn_of(triu)`` (an ``indirect_gn``
    Function, the Hessian's upper triangle or all of it), and the Functions ``extra`` (by name),
    compiled with the solver's when ``compiled``.

    IPOPT and its kin take the upper triangle, the SQP methods the whole matrix, some plugins no
    Hessian (tried in that order, the likely form first, as :func:`.problem.least_squares_nlp`);
    a plugin that takes no ``grad_f``/``jac_g`` (the SQP methods) makes its first derivatives itself
    (CasADi differentiating the NLP: correct, but its compiled code grows with the intervals)."""
    base = pb.solver_options_for(solver, verbose, None, tol=tol)
    first_full = solver in ("sqpmethod", "feasiblesqpmethod", "scpgen")
    attempts = [False, True, None] if first_full else [True, False, None]
    no_hessian, derivatives = False, True  # derivatives: the plugin takes grad_f and jac_g (IPOPT does, SQP not)
    while attempts:
        triu = attempts[0]
        if no_hessian and triu is not None:
            attempts.pop(0)
            continue
        gn = gn_of(True if triu is None else triu)
        fns = nlp_functions(gn, bool(triu))
        opts = {**base, **({"grad_f": fns["grad_f"], "jac_g": fns["jac_g"]} if derivatives else {})}
        if triu is not None:
            opts["hess_lag"] = fns["hess_lag"]
        pb.merge_options(opts, solver_options or {})
        try:
            S = ca.nlpsol(name, solver, nlp, opts)
        except RuntimeError as exc:
            msg = pb.casadi_reason(exc)
            if derivatives and ("grad_f" in msg or "jac_g" in msg):
                derivatives = False  # the same attempt, the solver making its own first derivatives
                continue
            attempts.pop(0)
            refused = pb.hessian_refused(msg, triu, solver)
            if refused is None:
                raise ValueError(f"solver {solver!r}: cannot be created ({msg})") from None
            no_hessian = no_hessian or refused == "none"
            continue
        if compiled:
            codegen.log.info("compiling the %s NLP's functions", name)
            out = codegen.compiled_nlpsol(name, solver, nlp, opts, interpreted=S, extra=extra,
                                          replace=functools.partial(_own_gradient, gn))
            return out if extra else (out, {})
        return S, {f.name(): f for f in extra}
    raise AssertionError("unreachable")
