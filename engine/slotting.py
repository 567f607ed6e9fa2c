"""Cycloidal slot forming with a rotating blade tool (filter tubes) — MATH.md §D, seed ``002_*``.

A multi-blade tool of radius ``R_u`` turns about a centre at distance ``A`` from the axis of a
rotating tubular part; the kinematic ratio is ``i = ω_d / ω_u``.  The blade tip cuts through the
wall, and the slot it leaves at the forming radius ``ρ`` (e.g. the bore) has length ``l``.
Synthesis: find ``A`` for a required ``l``.

Model and sign conventions (see ``docs/slotting.md``)
-----------------------------------------------------
Fixed frame: part centre ``O`` at the origin, tool centre at ``(A, 0)``.  ``R_u`` is signed like the
paper's "coordinate of the tool radius vector": ``R_u < 0`` for the external scheme (tool outside
the part, tip pointing at ``O``), ``R_u > 0`` for the internal scheme.  After the tool has turned by
``θ`` the tip is at ``P(θ) = (A + R_u cos θ, R_u sin θ)``; the part has turned by ``i·θ``.  The tip
crosses the circle of radius ``ρ`` where its polar angle ``β`` satisfies ``ρ sin β = R_u sin θ``;
in the part's frame that crossing lies at ``β − iθ``, which must be the slot's half angle
``φ = l / (2ρ)``.  Hence the paper's system (1)::

    θ = arcsin( (ρ / R_u) · sin(φ + iθ) )
    A = ρ cos(φ + iθ) − R_u cos θ                 (exact closure of the triangle O, O_u, P)

The paper prints the first equation as ``A = −R_u + sqrt(ρ² − (R_u sin θ)²)``; since
``R_u sin θ = ρ sin β`` this is ``−R_u + ρ|cos β|`` — the exact closure with ``cos θ`` replaced by 1.
It gives a tool setting whose real slot is shorter (at ``i = 0``, ``l = 20 mm``: 18.06 mm).  Both are
reported: ``A`` (exact, the default answer) and ``A_paper`` (as printed).  The ``θ`` equation — the
one the iteration solves and the one whose iteration counts the paper tabulates — is unchanged.

Down-cut (попутное, ПР) is ``i·R_u > 0`` (tip and part surface move the same way at the contact),
up-cut (встречное, ВР) is ``i·R_u < 0``; ``i = 0`` is a non-rotating part.

Units: mm and rad throughout.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from engine.errors import InputError
from engine.state import State, check_cancel

AFormula = Literal["exact", "paper"]

#: Default fixed-point iteration budget (the paper's runs need fewer than 10).
DEFAULT_MAX_ITER = 100
#: Grid used to bracket the roots of the θ equation for the cross-check / fallback solver.
_SCAN_POINTS = 4097


# --------------------------------------------------------------------------------------------------
# set-up and reduced parameters
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SlotSetup:
    """Geometry and kinematics of one slot-forming set-up.

    Parameters
    ----------
    rho:
        Forming radius ``ρ`` at which the slot length is specified, mm (> 0); the paper's
        ``ρ = R_d1``, the bore radius of the tube.
    tool_radius:
        Signed tool radius ``R_u``, mm: ``< 0`` external scheme, ``> 0`` internal scheme.
    ratio:
        Kinematic ratio ``i = ω_d / ω_u`` (part over tool angular speed), dimensionless.
    tol:
        Admissible relative error ``[Δ]`` of the fixed-point iteration, in (0, 1).
    part_radius:
        Nominal part radius ``R_d``, mm, for the reduced parameters of Table 1; ``None`` uses ``ρ``.
    max_iter:
        Iteration budget of the fixed-point iteration.
    a_formula:
        Which closure is returned as ``A``: ``"exact"`` (default) or ``"paper"`` (as printed).
    """

    rho: float
    tool_radius: float
    ratio: float = 0.0
    tol: float = 0.005
    part_radius: float | None = None
    max_iter: int = DEFAULT_MAX_ITER
    a_formula: AFormula = "exact"

    def validated(self) -> SlotSetup:
        """Return ``self`` after checking every field; raise :class:`InputError` naming the bad one."""
        _finite_positive(self.rho, "rho", "forming radius ρ")
        if not _finite(self.tool_radius) or self.tool_radius == 0.0:
            raise InputError(
                f"tool radius R_u must be a non-zero number of mm (negative = external scheme), "
                f"got {self.tool_radius!r}",
                field="tool_radius",
            )
        if self.tool_radius > 0 and math.isclose(self.tool_radius, self.rho, rel_tol=1e-12):
            raise InputError(
                f"internal scheme with R_u = ρ = {self.rho:g} mm: the tool circle coincides with the "
                "forming circle, no slot can be formed",
                field="tool_radius",
            )
        if not _finite(self.ratio):
            raise InputError(f"kinematic ratio i must be a finite number, got {self.ratio!r}", field="ratio")
        if not _finite(self.tol) or not 0.0 < self.tol < 1.0:
            raise InputError(f"admissible relative error [Δ] must lie in (0, 1), got {self.tol!r}", field="tol")
        if self.part_radius is not None:
            _finite_positive(self.part_radius, "part_radius", "part radius R_d")
        if not isinstance(self.max_iter, int | np.integer) or self.max_iter < 1:
            raise InputError(f"iteration budget must be an integer >= 1, got {self.max_iter!r}", field="max_iter")
        if self.a_formula not in ("exact", "paper"):
            raise InputError(
                f"A formula must be 'exact' or 'paper', got {self.a_formula!r}", field="a_formula"
            )
        return self

    @property
    def k(self) -> float:
        """``ρ / R_u`` (signed), the coefficient of the θ equation."""
        return self.rho / self.tool_radius

    @property
    def scheme(self) -> str:
        """``"external"`` (``R_u < 0``) or ``"internal"``."""
        return "external" if self.tool_radius < 0 else "internal"

    @property
    def mode(self) -> str:
        """``"down-cut"`` (``i·R_u > 0``), ``"up-cut"`` (``i·R_u < 0``) or ``"fixed part"`` (``i = 0``)."""
        return cutting_mode(self.ratio, self.tool_radius)

    def with_ratio(self, ratio: float) -> SlotSetup:
        """A copy with another kinematic ratio ``i``."""
        return SlotSetup(
            self.rho, self.tool_radius, float(ratio), self.tol, self.part_radius, self.max_iter, self.a_formula
        )


def cutting_mode(ratio: float, tool_radius: float) -> str:
    """Name the cutting mode for kinematic ratio ``i`` and signed tool radius ``R_u`` (mm).

    Returns ``"down-cut"`` (попутное резание, ПР) when ``i·R_u > 0``, ``"up-cut"`` (встречное, ВР)
    when ``i·R_u < 0`` and ``"fixed part"`` when ``i = 0``.
    """
    s = ratio * tool_radius
    if s > 0:
        return "down-cut"
    if s < 0:
        return "up-cut"
    return "fixed part"


@dataclass(frozen=True)
class ReducedParameters:
    """The reduced parameters of the paper's Table 1 (all dimensionless).

    Attributes
    ----------
    i1:
        ``R_u / R_d``: geometric ratio of the engagement = reduced tool radius.
    A_tilde_nominal:
        ``1 − i1``: reduced nominal centre distance ``A / R_d`` (tool tip on the nominal radius).
    i:
        ``ω_d / ω_u``: kinematic ratio.
    I:
        ``V_u / V_d = i1 / i``: ratio of peripheral speeds (``None`` for ``i = 0``).
    rho_tilde:
        ``ρ / R_d``: reduced forming radius.
    """

    i1: float
    A_tilde_nominal: float
    i: float
    I: float | None  # noqa: E741 - the paper's symbol
    rho_tilde: float


def reduced_parameters(setup: SlotSetup) -> ReducedParameters:
    """Table 1 of the paper for ``setup`` (``R_d`` = ``setup.part_radius`` or ``ρ``)."""
    s = setup.validated()
    rd = s.part_radius if s.part_radius is not None else s.rho
    i1 = s.tool_radius / rd
    return ReducedParameters(
        i1=i1,
        A_tilde_nominal=1.0 - i1,
        i=s.ratio,
        I=(i1 / s.ratio) if s.ratio != 0 else None,
        rho_tilde=s.rho / rd,
    )


# --------------------------------------------------------------------------------------------------
# the paper's fixed-point iteration
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class IterationResult:
    """Outcome of the fixed-point iteration (2) of the paper.

    Attributes
    ----------
    theta:
        Last iterate ``θ_{J+1}``, rad (``nan`` when the arcsin argument left [−1, 1]).
    iterations:
        ``J``: the index of the last step ``θ_{J+1} = T(θ_J)``, counted from ``j = 0`` (``θ_0 = 0``).
        For ``i = 0`` the step ``j = 0`` gives the exact answer and ``j = 1`` confirms it, so
        ``J = 1`` — the paper's "finishes on the first iteration".
    converged:
        ``|Δ_J| <= [Δ]`` was reached within the budget.
    status:
        ``"converged"``, ``"domain"`` (arcsin argument outside [−1, 1]) or ``"max_iter"``.
    error_history:
        Signed relative errors ``Δ_j = (θ_{j+1} − θ_j) / θ_{j+1}``, ``j = 0 … J`` (``Δ_0 = 1``).
    thetas:
        ``θ_0 … θ_{J+1}``, rad.
    bad_argument:
        The arcsin argument that left [−1, 1] (status ``"domain"``), else ``None``.
    """

    theta: float
    iterations: int
    converged: bool
    status: str
    error_history: np.ndarray
    thetas: np.ndarray
    bad_argument: float | None = None


def fixed_point_iteration(
    phi: float, ratio: float, k: float, tol: float, max_iter: int = DEFAULT_MAX_ITER
) -> IterationResult:
    """Iterate ``θ_{j+1} = arcsin(k·sin(φ + i·θ_j))`` from ``θ_0 = 0`` exactly as the paper's Fig. 3.

    Parameters
    ----------
    phi:
        Half central angle of the slot ``φ = l / (2ρ)``, rad (non-zero).
    ratio:
        Kinematic ratio ``i``.
    k:
        ``ρ / R_u`` (signed).
    tol:
        Admissible relative error ``[Δ]``; the loop stops when ``|Δ_j| <= [Δ]``.
    max_iter:
        Maximum number of steps.

    Returns
    -------
    IterationResult
    """
    theta = 0.0
    thetas = [theta]
    errors: list[float] = []
    for _ in range(max_iter):
        arg = k * math.sin(phi + ratio * theta)
        if abs(arg) > 1.0:
            return IterationResult(
                math.nan, len(errors), False, "domain", np.asarray(errors), np.asarray(thetas), float(arg)
            )
        new = math.asin(arg)
        if new == 0.0:  # only when φ + iθ is a multiple of π: Δ undefined, θ = 0 is a fixed point
            delta = 0.0 if theta == 0.0 else math.copysign(math.inf, -theta)
        else:
            delta = (new - theta) / new + 0.0  # + 0.0 turns −0.0 into 0.0
        errors.append(delta)
        thetas.append(new)
        theta = new
        if abs(delta) <= tol:
            return IterationResult(
                theta, len(errors) - 1, True, "converged", np.asarray(errors), np.asarray(thetas)
            )
    return IterationResult(theta, len(errors) - 1, False, "max_iter", np.asarray(errors), np.asarray(thetas))


# --------------------------------------------------------------------------------------------------
# bracketing solver (cross-check and fallback)
# --------------------------------------------------------------------------------------------------
def theta_roots(phi: float, ratio: float, k: float) -> np.ndarray:
    """Every root of ``sin θ = k·sin(φ + iθ)`` on the arcsin branch ``θ ∈ [−π/2, π/2]``, rad.

    Roots are bracketed on a fine grid and polished with :func:`scipy.optimize.brentq`
    (``xtol = 1e-14``).  This is the same equation as ``θ = arcsin(k sin(φ + iθ))`` (the arcsin form
    is not defined where ``|k sin(·)| > 1``; the sine form is, and has no root there).
    """
    from scipy.optimize import brentq  # lazy: scipy.optimize is a heavy import

    def f(t: float) -> float:
        return math.sin(t) - k * math.sin(phi + ratio * t)

    grid = np.linspace(-0.5 * math.pi, 0.5 * math.pi, _SCAN_POINTS)
    vals = np.sin(grid) - k * np.sin(phi + ratio * grid)
    roots: list[float] = [float(g) for g in grid[vals == 0.0]]
    rtol = 4 * np.finfo(float).eps
    for n in np.nonzero(vals[:-1] * vals[1:] < 0.0)[0]:
        roots.append(float(brentq(f, float(grid[n]), float(grid[n + 1]), xtol=1e-14, rtol=rtol)))
    return np.sort(np.asarray(roots, dtype=float))


def contraction_factor(theta: float, phi: float, ratio: float, k: float) -> float:
    """``|T'(θ)| = |k·i·cos(φ + iθ) / cos θ|`` of the iteration map at ``θ`` (< 1: converges locally)."""
    c = math.cos(theta)
    if c == 0.0:
        return math.inf
    return abs(k * ratio * math.cos(phi + ratio * theta) / c)


# --------------------------------------------------------------------------------------------------
# closure: the centre distance
# --------------------------------------------------------------------------------------------------
def centre_distance(theta: float, phi: float, ratio: float, rho: float, tool_radius: float) -> float:
    """Exact centre distance ``A = ρ cos(φ + iθ) − R_u cos θ``, mm (signed like the set-up)."""
    return rho * math.cos(phi + ratio * theta) - tool_radius * math.cos(theta)


def centre_distance_paper(theta: float, rho: float, tool_radius: float) -> float:
    """The paper's printed closure ``A = −R_u + sqrt(ρ² − (R_u sin θ)²)``, mm (``nan`` if undefined)."""
    d = rho * rho - (tool_radius * math.sin(theta)) ** 2
    if d < 0.0:
        return math.nan
    return -tool_radius + math.sqrt(d)


# --------------------------------------------------------------------------------------------------
# one row of the table
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SlotRow:
    """The answer for one slot length.

    Attributes
    ----------
    l:
        Required slot length, mm.
    phi:
        ``l / (2ρ)``, rad.
    ratio:
        Kinematic ratio ``i``.
    A:
        Centre distance, mm, by the set-up's ``a_formula`` from the reported ``theta``; ``nan`` when
        no answer exists.
    A_exact, A_paper:
        Both closures from ``theta``, mm.
    A_check:
        Exact closure from the bracketing solver's root, mm (``nan`` if none).
    theta:
        The reported contact angle, rad: the iteration's when it converged, else the fallback's.
    theta_check:
        The bracketing solver's root nearest to ``theta`` (or the chosen fallback root), rad.
    iterations, converged, status, error_history:
        From the fixed-point iteration (see :class:`IterationResult`).
    method:
        ``"iteration"``, ``"fallback"`` (bracketing solver) or ``"none"``.
    agrees:
        Iteration and bracketing solver agree within the [Δ]-consistent bound ``theta_bound``.
    theta_bound:
        ``max(1, q / (1 − q))·[Δ]·|θ|``, rad, with ``q`` the contraction factor at the root.
    contraction:
        ``q = |T'(θ*)|`` at the bracketing root (``nan`` if none).
    n_roots:
        How many roots the θ equation has on ``[−π/2, π/2]`` (with the admissible sign of ``A``).
    mode:
        ``"down-cut"``, ``"up-cut"`` or ``"fixed part"``.
    message:
        Plain-language note for the user ("" when all is well).
    """

    l: float
    phi: float
    ratio: float
    A: float
    A_exact: float
    A_paper: float
    A_check: float
    theta: float
    theta_check: float
    iterations: int
    converged: bool
    status: str
    error_history: np.ndarray
    method: str
    agrees: bool
    theta_bound: float
    contraction: float
    n_roots: int
    mode: str
    message: str = ""

    @property
    def ok(self) -> bool:
        """True when the row has an answer."""
        return self.method != "none"

    def as_dict(self) -> dict[str, object]:
        """JSON-ready dict (``nan`` becomes ``None``); lengths in mm, angles in rad."""
        return {
            "l_mm": self.l,
            "phi_rad": self.phi,
            "ratio": self.ratio,
            "A_mm": _none_if_nan(self.A),
            "A_exact_mm": _none_if_nan(self.A_exact),
            "A_paper_mm": _none_if_nan(self.A_paper),
            "A_check_mm": _none_if_nan(self.A_check),
            "theta_rad": _none_if_nan(self.theta),
            "theta_check_rad": _none_if_nan(self.theta_check),
            "iterations": int(self.iterations),
            "converged": bool(self.converged),
            "status": self.status,
            "method": self.method,
            "agrees": bool(self.agrees),
            "contraction": _none_if_nan(self.contraction),
            "n_roots": int(self.n_roots),
            "mode": self.mode,
            "message": self.message,
            "error_history": [_none_if_nan(float(d)) for d in self.error_history],
        }


def _admissible(theta: float, phi: float, ratio: float, rho: float, tool_radius: float) -> bool:
    """The tool centre stays on the side it has at ``l → 0`` (``A₀ = ρ − R_u``)."""
    a = centre_distance(theta, phi, ratio, rho, tool_radius)
    a0 = rho - tool_radius
    return a * a0 > 0.0


def solve_slot(length: float, setup: SlotSetup) -> SlotRow:
    """Centre distance ``A`` giving slot length ``l`` (mm) for ``setup``.

    Runs the paper's fixed-point iteration and the bracketing solver.  When the iteration
    converges its answer is reported and the bracketing root is the cross-check; when it does not
    (``|k·i| >= 1``, arcsin argument outside [−1, 1], budget exhausted) the bracketing root is the
    fallback, or the row says why no centre distance gives that length.

    Parameters
    ----------
    length:
        Required slot length ``l`` at radius ``ρ``, mm (> 0, below the circumference ``2πρ``).
    setup:
        The set-up.

    Returns
    -------
    SlotRow
    """
    s = setup.validated()
    if not _finite(length) or length <= 0.0:
        raise InputError(f"slot length l must be a positive number of mm, got {length!r}", field="length")
    if length >= 2.0 * math.pi * s.rho:
        raise InputError(
            f"slot length l = {length:g} mm is not shorter than the circumference 2πρ = "
            f"{2 * math.pi * s.rho:.4g} mm",
            field="length",
        )
    rho, ru, i, k = s.rho, s.tool_radius, s.ratio, s.k
    phi = length / (2.0 * rho)
    mode = s.mode

    it = fixed_point_iteration(phi, i, k, s.tol, s.max_iter)
    roots = [float(r) for r in theta_roots(phi, i, k) if _admissible(float(r), phi, i, rho, ru)]

    # choose the bracketing root
    root = math.nan
    if roots:
        if it.converged:
            root = min(roots, key=lambda r: abs(r - it.theta))
        else:
            # the branch that continues the fixed-part solution: θ has the sign of k·sin φ
            sgn = math.copysign(1.0, k * math.sin(phi))
            same = [r for r in roots if r * sgn > 0.0]
            root = min(same or roots, key=abs)
    q = contraction_factor(root, phi, i, k) if roots else math.nan
    if roots and q < 1.0:
        bound = max(1.0, q / (1.0 - q)) * s.tol * abs(root)
    else:
        bound = math.inf if roots else math.nan
    a_check = centre_distance(root, phi, i, rho, ru) if roots else math.nan
    kia = abs(k * i)

    notes: list[str] = []
    if it.converged and _admissible(it.theta, phi, i, rho, ru):
        theta, method = it.theta, "iteration"
        agrees = bool(roots) and abs(it.theta - root) <= bound * (1.0 + 1e-9) + 1e-15
        if kia >= 1.0:
            notes.append(
                f"|ρ·i/R_u| = {kia:.4g} >= 1: outside the region where the iteration is sure to converge; "
                "it converged here (checked against the bracketing solver)"
            )
        if not agrees:
            notes.append(
                "the iteration stopped on its [Δ] test but disagrees with the bracketing solver "
                f"(θ = {it.theta:.6g} vs {root:.6g} rad); use A_check"
            )
    else:
        agrees = False
        if it.converged:
            why = "the iteration converged to a root with the tool centre on the wrong side"
        elif it.status == "domain":
            why = (
                f"the iteration cannot proceed: arcsin argument {it.bad_argument:.4g} is outside [-1, 1] "
                f"at step j = {it.iterations}"
            )
        elif kia >= 1.0:
            why = (
                f"the iteration does not converge: |ρ·i/R_u| = {kia:.4g} >= 1 (the map is not a "
                f"contraction), {s.max_iter} steps"
            )
        else:
            why = f"the iteration did not reach [Δ] = {s.tol:g} in {s.max_iter} steps"
        if roots:
            theta, method = root, "fallback"
            notes.append(why + "; A is the bracketing solver's answer")
            if len(roots) > 1:
                notes.append(
                    f"the θ equation has {len(roots)} admissible roots here (looping trajectory); the one "
                    "continuing the fixed-part branch is reported"
                )
        else:
            theta, method = math.nan, "none"
            lmax = max_reachable_length(s)
            reach = f" (longest reachable ≈ {lmax:.4g} mm)" if _finite(lmax) else ""
            notes.append(
                f"{why}; slot length l = {length:g} mm cannot be reached: no contact angle θ in [-90°, 90°] "
                f"satisfies sin θ = (ρ/R_u)·sin(φ + iθ) with this tool radius and ratio{reach}"
            )

    if method == "none":
        a_exact = a_paper = a = math.nan
    else:
        a_exact = centre_distance(theta, phi, i, rho, ru)
        a_paper = centre_distance_paper(theta, rho, ru)
        a = a_exact if s.a_formula == "exact" else a_paper
    return SlotRow(
        l=float(length),
        phi=phi,
        ratio=i,
        A=a,
        A_exact=a_exact,
        A_paper=a_paper,
        A_check=a_check,
        theta=theta,
        theta_check=root,
        iterations=it.iterations,
        converged=it.converged,
        status=it.status,
        error_history=it.error_history,
        method=method,
        agrees=agrees,
        theta_bound=bound,
        contraction=q,
        n_roots=len(roots),
        mode=mode,
        message="; ".join(notes),
    )


def max_reachable_length(setup: SlotSetup, n: int = 20001) -> float:
    """Longest slot length reachable on the arcsin branch, mm (scan of ``θ``; ``inf`` if unlimited).

    For each contact angle ``θ ∈ [−π/2, π/2]`` the polar angle ``β`` of the crossing solves
    ``ρ sin β = R_u sin θ`` (two branches), the slot half angle is ``β − iθ`` and the centre distance
    must keep its side; the largest ``2ρ|β − iθ|`` is returned (capped at ``2πρ``).
    """
    s = setup.validated()
    th = np.linspace(-0.5 * math.pi, 0.5 * math.pi, n)
    sb = np.sin(th) / s.k
    ok = np.abs(sb) <= 1.0
    th, sb = th[ok], sb[ok]
    best = 0.0
    a0 = s.rho - s.tool_radius
    for beta in (np.arcsin(sb), np.pi - np.arcsin(sb)):
        a = s.rho * np.cos(beta) - s.tool_radius * np.cos(th)
        adm = a * a0 > 0
        if np.any(adm):
            half = np.abs(beta - s.ratio * th)[adm]
            half = half[half < 2 * math.pi]
            if half.size:
                best = max(best, float(np.max(np.minimum(half, math.pi))))
    return 2.0 * s.rho * best


# --------------------------------------------------------------------------------------------------
# tables, curves, histories
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SlotTable:
    """Table of ``A`` and ``j`` over slot lengths (the paper's Tables 2 and 3)."""

    setup: SlotSetup
    reduced: ReducedParameters
    rows: tuple[SlotRow, ...]

    @property
    def lengths(self) -> np.ndarray:
        """Slot lengths, mm."""
        return np.array([r.l for r in self.rows])

    @property
    def A(self) -> np.ndarray:  # noqa: N802 - the paper's symbol
        """Centre distances, mm (``nan`` where unreachable)."""
        return np.array([r.A for r in self.rows])

    @property
    def iterations(self) -> np.ndarray:
        """Iteration counts ``j``."""
        return np.array([r.iterations for r in self.rows], dtype=int)


def parse_range(text: str, what: str = "length", field_name: str = "length") -> np.ndarray:
    """Parse ``"FROM:TO:STEP"`` (inclusive of TO within rounding) or a single number or ``a,b,c``.

    Raises
    ------
    InputError
        On malformed text, a non-positive step, more than 10 000 values, or an empty range.
    """
    t = str(text).strip()
    try:
        if ":" in t:
            parts = [float(p) for p in t.split(":")]
            if len(parts) != 3:
                raise ValueError
            a, b, step = parts
            if not all(_finite(v) for v in parts):
                raise ValueError
            if step <= 0:
                raise InputError(f"{what} range step must be > 0, got {step:g} in {text!r}", field=field_name)
            if b < a:
                raise InputError(f"{what} range ends before it starts: {text!r}", field=field_name)
            n = int(math.floor((b - a) / step + 1e-9)) + 1
            if n > 10000:
                raise InputError(f"{what} range {text!r} has {n} values; at most 10000", field=field_name)
            return a + step * np.arange(n)
        vals = [float(p) for p in t.replace(";", ",").split(",") if p.strip()]
    except InputError:
        raise
    except ValueError:
        raise InputError(
            f"cannot read {what} {text!r}: use FROM:TO:STEP, a number, or a comma-separated list",
            field=field_name,
        ) from None
    if not vals or not all(_finite(v) for v in vals):
        raise InputError(f"cannot read {what} {text!r}: no finite values", field=field_name)
    return np.asarray(vals, dtype=float)


def slot_table(lengths: Sequence[float] | np.ndarray, setup: SlotSetup, state: State | None = None) -> SlotTable:
    """One :class:`SlotRow` per slot length (mm) for ``setup`` — the paper's Tables 2/3."""
    s = setup.validated()
    ls = [float(v) for v in np.atleast_1d(np.asarray(lengths, dtype=float))]
    if not ls:
        raise InputError("no slot lengths given", field="length")
    rows = []
    for n, l in enumerate(ls):
        check_cancel(state)
        try:
            rows.append(solve_slot(l, s))
        except InputError as exc:
            raise exc.at(field="length") from None
        if state is not None:
            state.progress((n + 1) / len(ls), f"l = {l:g} mm")
    return SlotTable(s, reduced_parameters(s), tuple(rows))


@dataclass(frozen=True)
class RatioCurves:
    """``A(i)`` for several slot lengths (the paper's Fig. 4).

    Attributes
    ----------
    lengths:
        Slot lengths, mm, shape ``(m,)``.
    ratios:
        Kinematic ratios ``i``, shape ``(n,)``.
    A:
        Centre distances, mm, shape ``(m, n)`` (``nan`` where unreachable).
    iterations:
        Iteration counts, shape ``(m, n)``.
    method:
        ``"iteration"``/``"fallback"``/``"none"`` per point, shape ``(m, n)``.
    """

    lengths: np.ndarray
    ratios: np.ndarray
    A: np.ndarray
    iterations: np.ndarray
    method: np.ndarray


def ratio_curves(
    lengths: Sequence[float] | np.ndarray,
    ratios: Sequence[float] | np.ndarray,
    setup: SlotSetup,
    state: State | None = None,
) -> RatioCurves:
    """``A(i)`` over ``ratios`` for every slot length in ``lengths`` (mm); ``setup.ratio`` is ignored."""
    s = setup.validated()
    ls = np.atleast_1d(np.asarray(lengths, dtype=float))
    rs = np.atleast_1d(np.asarray(ratios, dtype=float))
    a = np.full((ls.size, rs.size), np.nan)
    its = np.zeros((ls.size, rs.size), dtype=int)
    meth = np.empty((ls.size, rs.size), dtype=object)
    total = max(ls.size * rs.size, 1)
    for m, l in enumerate(ls):
        for n, r in enumerate(rs):
            if (m * rs.size + n) % 50 == 0:
                check_cancel(state)
            try:
                row = solve_slot(float(l), s.with_ratio(float(r)))
            except InputError as exc:
                raise exc.at(field="length") from None
            a[m, n], its[m, n], meth[m, n] = row.A, row.iterations, row.method
        if state is not None:
            state.progress((m + 1) * rs.size / total, f"A(i) for l = {l:g} mm")
    return RatioCurves(ls, rs, a, its, meth)


def error_histories(
    length: float, ratios: Sequence[float] | np.ndarray, setup: SlotSetup
) -> dict[float, IterationResult]:
    """The iteration's error history ``Δ(j)`` at slot length ``l`` (mm) for each ratio (Fig. 5)."""
    s = setup.validated()
    phi = float(length) / (2.0 * s.rho)
    return {
        float(r): fixed_point_iteration(phi, float(r), s.k, s.tol, s.max_iter)
        for r in np.atleast_1d(np.asarray(ratios, dtype=float))
    }


# --------------------------------------------------------------------------------------------------
# kinematics of the slot
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Trajectory:
    """The forming point's path ``S`` in the part's frame.

    Attributes
    ----------
    theta:
        Tool angles, rad.
    x, y:
        Tip coordinates in the part frame, mm (part centre at the origin, tool centre on +x at
        ``θ = 0``).
    r:
        Distance of the tip from the part axis, mm.
    crossing_theta:
        ``θ*`` where the tip crosses radius ``ρ`` (``nan`` if it never does), rad, ``>= 0``.
    slot_half_angle:
        Part-frame polar angle of the crossing, rad (the slot spans ``±`` this at radius ``ρ``).
    slot_length:
        Slot length at radius ``ρ``, mm (arc ``2ρ·half angle``; ``nan`` without a crossing).
    """

    theta: np.ndarray
    x: np.ndarray
    y: np.ndarray
    r: np.ndarray
    crossing_theta: float
    slot_half_angle: float
    slot_length: float


def tip_in_part_frame(
    theta: np.ndarray | float, A: float, tool_radius: float, ratio: float
) -> tuple[np.ndarray, np.ndarray]:
    """Tip position in the part frame after tool rotation ``θ`` (rad): ``Rot(−iθ)·(A + R_u cos θ, R_u sin θ)``.

    Returns ``(x, y)`` in mm.
    """
    th = np.asarray(theta, dtype=float)
    px = A + tool_radius * np.cos(th)
    py = tool_radius * np.sin(th)
    c, s = np.cos(ratio * th), np.sin(ratio * th)
    return c * px + s * py, -s * px + c * py


def forward_slot_length(A: float, setup: SlotSetup) -> float:
    """Slot length (mm) a centre distance ``A`` (mm) actually produces at radius ``ρ``.

    Independent of system (1): the crossing of the tip circle with radius ``ρ`` from the law of
    cosines (``cos θ* = (ρ² − A² − R_u²) / (2 A R_u)``), then its polar angle in the part frame.
    Returns ``nan`` when the tip circle never reaches radius ``ρ``.
    """
    s = setup.validated()
    ru = s.tool_radius
    if A == 0.0:
        return math.nan
    c = (s.rho**2 - A * A - ru * ru) / (2.0 * A * ru)
    if abs(c) > 1.0:
        return math.nan
    th = math.acos(c)
    x, y = tip_in_part_frame(th, A, ru, s.ratio)
    return 2.0 * s.rho * abs(math.atan2(float(y), float(x)))


def slot_trajectory(A: float, setup: SlotSetup, span: float = 1.6, n: int = 801) -> Trajectory:
    """Path of the forming point in the part frame for centre distance ``A`` (mm).

    Parameters
    ----------
    A:
        Centre distance, mm (signed as in :func:`centre_distance`).
    setup:
        The set-up (``ratio`` sets the part rotation).
    span:
        The tool angle range is ``±span·θ*`` (``θ*`` the crossing of radius ``ρ``); if the part
        radius ``R_d`` is larger than ``ρ`` the range also reaches the entry into ``R_d``.
    n:
        Number of samples.
    """
    s = setup.validated()
    ru = s.tool_radius
    if not _finite(A) or A == 0.0:
        raise InputError(f"centre distance A must be a non-zero number of mm, got {A!r}", field="A")

    def crossing(radius: float) -> float:
        c = (radius**2 - A * A - ru * ru) / (2.0 * A * ru)
        return math.acos(c) if abs(c) <= 1.0 else math.nan

    th_star = crossing(s.rho)
    lim = span * th_star if _finite(th_star) and th_star > 0 else 0.5 * math.pi
    if s.part_radius is not None and s.part_radius > s.rho:
        th_out = crossing(s.part_radius)
        if _finite(th_out):
            lim = max(lim, min(1.05 * th_out, math.pi))
    lim = min(lim, math.pi)
    th = np.linspace(-lim, lim, n)
    x, y = tip_in_part_frame(th, A, ru, s.ratio)
    if _finite(th_star):
        xs, ys = tip_in_part_frame(th_star, A, ru, s.ratio)
        half = abs(math.atan2(float(ys), float(xs)))
    else:
        half = math.nan
    return Trajectory(th, x, y, np.hypot(x, y), th_star, half, 2.0 * s.rho * half)


# --------------------------------------------------------------------------------------------------
# everything the dialog shows, in one call
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SlotStudy:
    """Table, ``A(i)`` curves, error histories and one trajectory for one set-up."""

    table: SlotTable
    curves: RatioCurves
    histories: dict[float, IterationResult]
    history_length: float
    trajectory: Trajectory | None
    trajectory_row: SlotRow | None


def slot_study(
    setup: SlotSetup,
    lengths: Sequence[float] | np.ndarray,
    curve_lengths: Sequence[float] | np.ndarray,
    curve_ratios: Sequence[float] | np.ndarray,
    history_ratios: Sequence[float] | np.ndarray,
    focus_length: float,
    state: State | None = None,
) -> SlotStudy:
    """Compute the table (Tables 2/3), ``A(i)`` (Fig. 4), ``Δ(j)`` (Fig. 5) and the path ``S``.

    Parameters
    ----------
    setup:
        The set-up; ``setup.ratio`` is the ratio of the table and of the trajectory.
    lengths:
        Slot lengths of the table, mm.
    curve_lengths, curve_ratios:
        Slot lengths (mm) and ratios of the ``A(i)`` curves.
    history_ratios:
        Ratios whose error histories are shown, at slot length ``focus_length``.
    focus_length:
        Slot length (mm) of the error histories and of the trajectory.
    state:
        Progress / cancellation.
    """
    from engine.state import SubState

    s = setup.validated()
    sub = state if state is None else SubState(state, 0.0, 0.3)
    table = slot_table(lengths, s, sub)
    check_cancel(state)
    sub = state if state is None else SubState(state, 0.3, 0.95)
    curves = ratio_curves(curve_lengths, curve_ratios, s, sub)
    check_cancel(state)
    row = solve_slot(float(focus_length), s)
    histories = error_histories(float(focus_length), history_ratios, s)
    traj = slot_trajectory(row.A, s) if row.ok and math.isfinite(row.A) else None  # the reported A
    if state is not None:
        state.progress(1.0, "done")
    return SlotStudy(table, curves, histories, float(focus_length), traj, row)


# --------------------------------------------------------------------------------------------------
# CSV output
# --------------------------------------------------------------------------------------------------
CSV_COLUMNS = (
    "l_mm",
    "A_mm",
    "A_exact_mm",
    "A_paper_mm",
    "A_check_mm",
    "theta_rad",
    "theta_check_rad",
    "iterations",
    "converged",
    "method",
    "agrees",
    "mode",
    "message",
)


def table_csv(table: SlotTable) -> str:
    """The table as CSV text (header + one line per row; empty cells where there is no answer)."""
    import csv
    import io

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    red = table.reduced
    s = table.setup
    w.writerow(
        [
            f"# rho_mm={s.rho:g}",
            f"tool_radius_mm={s.tool_radius:g}",
            f"ratio={s.ratio:g}",
            f"tol={s.tol:g}",
            f"a_formula={s.a_formula}",
            f"i1={red.i1:.6g}",
            f"A_tilde_nominal={red.A_tilde_nominal:.6g}",
            f"I={'' if red.I is None else f'{red.I:.6g}'}",
            f"rho_tilde={red.rho_tilde:.6g}",
        ]
    )
    w.writerow(CSV_COLUMNS)
    for r in table.rows:
        d = r.as_dict()
        w.writerow(["" if d[c] is None else _csv_cell(d[c]) for c in CSV_COLUMNS])
    return buf.getvalue()


def write_table_csv(path: str | Path, table: SlotTable) -> Path:
    """Write :func:`table_csv` to ``path`` atomically (temp file + rename)."""
    from engine.fileio import atomic_write_text

    try:
        return atomic_write_text(path, table_csv(table))
    except OSError as exc:
        raise InputError(f"cannot write the CSV file: {exc.strerror or exc}", file=str(path)) from None


# --------------------------------------------------------------------------------------------------
def _finite(v: object) -> bool:
    try:
        return math.isfinite(float(v))  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False


def _finite_positive(v: object, name: str, what: str) -> None:
    if not _finite(v) or float(v) <= 0.0:  # type: ignore[arg-type]
        raise InputError(f"{what} must be a positive number of mm, got {v!r}", field=name)


def _none_if_nan(v: float) -> float | None:
    return None if v is None or not math.isfinite(v) else float(v)


def _csv_cell(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return str(v)


__all__ = [
    "IterationResult",
    "RatioCurves",
    "ReducedParameters",
    "SlotRow",
    "SlotSetup",
    "SlotStudy",
    "SlotTable",
    "Trajectory",
    "centre_distance",
    "centre_distance_paper",
    "contraction_factor",
    "cutting_mode",
    "error_histories",
    "fixed_point_iteration",
    "forward_slot_length",
    "max_reachable_length",
    "parse_range",
    "ratio_curves",
    "reduced_parameters",
    "slot_study",
    "slot_table",
    "solve_slot",
    "slot_trajectory",
    "table_csv",
    "theta_roots",
    "tip_in_part_frame",
    "write_table_csv",
]
