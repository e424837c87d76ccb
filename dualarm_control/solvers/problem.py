"""The inputs of one control cycle: :class:`ControlProblem` and the checks of its inputs.

A solver is a pure function of the problem (Jacobian, reference twist, velocity bounds,
repulsive velocity) to joint velocities (:mod:`dualarm_control.solvers.base`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dualarm_control.arrays import FloatArray
from dualarm_control.limits.base import DeferredRows


@dataclass(slots=True)
class ControlProblem:
    """Inputs of one control cycle.

    A per-cycle record: slotted, not frozen (cheaper to build, docs/bench.md); read-only by convention.

    Attributes:
        jacobian: relative Jacobian J of eq (5), (6, n); (6 k, n) for k relative tasks stacked
            (the benchmark's 3- and 4-arm chains).
        reference: closed-loop reference twist xd* + K e of eq (13)/(26) [m/s; rad/s], (6,) or (6 k,).
        lower, upper: joint velocity bounds Qd_min, Qd_max of eq (23) [rad/s], (n,).
        repulsive: repulsive joint velocity qd_r of eq (25) [rad/s], (n,); used by the
            hierarchical solver's secondary task only.
        inequality_jacobian: A_ie of paper 001 eq (13), (m_ie, n), or None (no inequality
            rows; the solvers of paper 000 ignore them).
        inequality_bound: h of ``A_ie qd <= h``, k(b - f) - df/dt of eq (13), (m_ie,).
        equality_weights: slack weight of each row of ``jacobian`` (>= 0), (m,), or None (1).
        inequality_weights: slack weight of each inequality row (> 0), (m_ie,), or None.
        limit_rows: hard rows ``limit_rows @ qd <= limit_bound`` of the limits beyond the box, (m_l, n), or
            None: the collision limit's velocity damper (:mod:`dualarm_control.limits.collision`). Every
            solver takes them as hard constraints (docs/collision.md, "Limits").
        limit_bound: their right-hand side [m/s], (m_l,).
        limit_labels: what each row keeps apart (the link pair), m_l strings, for reports.
        limit_deferred: the rows given instead as :class:`~dualarm_control.limits.DeferredRows`
            (limit_rows None): built only when a solver needs them (:meth:`limit_matrix`); where
            their speed bound vouches for a qd (:meth:`limit_excess`), they are not.
        secondary_jacobian: J_2 of the second priority (the absolute pose under the relative one, issue 41),
            (m_2, n), rows already scaled by the square root of their weight, or None (one priority).
            Every solver realises it in the optimal set of the first priority
            (:mod:`dualarm_control.solvers.priority`).
        secondary_reference: its reference r_2 = k (b - f) - df/dt [m/s; rad/s], (m_2,).
    """

    jacobian: FloatArray
    reference: FloatArray
    lower: FloatArray
    upper: FloatArray
    repulsive: FloatArray
    inequality_jacobian: FloatArray | None = None
    inequality_bound: FloatArray | None = None
    equality_weights: FloatArray | None = None
    inequality_weights: FloatArray | None = None
    limit_rows: FloatArray | None = None
    limit_bound: FloatArray | None = None
    limit_labels: tuple[str, ...] = ()
    limit_deferred: DeferredRows | None = None
    secondary_jacobian: FloatArray | None = None
    secondary_reference: FloatArray | None = None

    @property
    def has_secondary(self) -> bool:
        """Whether the problem has a second priority (:attr:`secondary_jacobian`)."""
        return self.secondary_jacobian is not None and self.secondary_reference is not None

    def stacked(self) -> ControlProblem:
        """Both priorities as one equality task [J; J_2], [r; r_2] (no second priority): what a level below
        both (the hierarchical solvers' repulsive level) keeps. Itself without a second priority."""
        if self.secondary_jacobian is None or self.secondary_reference is None:
            return self
        weights = None if self.equality_weights is None else np.concatenate(
            (self.equality_weights, np.ones(self.secondary_reference.shape[0])))
        return ControlProblem(np.vstack((self.jacobian, self.secondary_jacobian)),
                              np.concatenate((self.reference, self.secondary_reference)), self.lower, self.upper,
                              self.repulsive, self.inequality_jacobian, self.inequality_bound, weights,
                              self.inequality_weights, self.limit_rows, self.limit_bound, self.limit_labels,
                              self.limit_deferred)

    @property
    def has_limit_rows(self) -> bool:
        """Whether the problem has at least one hard limit row."""
        return (self.limit_rows is not None and self.limit_rows.shape[0] > 0) or self.limit_deferred is not None

    def limit_matrix(self) -> FloatArray | None:
        """A of the hard limit rows (m_l, n), built now when deferred; None without rows."""
        if self.limit_rows is None and self.limit_deferred is not None:
            self.limit_rows = self.limit_deferred.matrix
        return self.limit_rows

    def limit_excess(self, qd: FloatArray) -> float:
        """How far qd (n,) [rad/s] breaks the hard limit rows at their worst: max(A qd - b, 0) [m/s]
        (0 without building deferred rows where their speed bound vouches for qd)."""
        if self.limit_bound is None or not self.has_limit_rows:
            return 0.0
        if self.limit_rows is None and self.limit_deferred is not None:  # built only where the speed bounds fail
            return self.limit_deferred.excess(qd)
        a = self.limit_matrix()
        assert a is not None
        return float((a @ qd - self.limit_bound).max(initial=0.0))

    def without_limit_rows(self) -> ControlProblem:
        """The same problem without the limits' rows (its relaxation: a solution of it that meets the
        rows solves the problem with them, as the QPs are convex)."""
        return ControlProblem(self.jacobian, self.reference, self.lower, self.upper, self.repulsive,
                              self.inequality_jacobian, self.inequality_bound, self.equality_weights,
                              self.inequality_weights, secondary_jacobian=self.secondary_jacobian,
                              secondary_reference=self.secondary_reference)

    def problem_with_invalid_input(self) -> str:
        """Return a description of what is wrong with the inputs, or '' when they are usable.

        Runs every cycle, so the common case costs four reductions: shapes are compared as
        tuples, and one sum is finite only if J, the reference and the repulsive velocity are
        finite and g = max(lower - upper) is finite (a NaN or an infinite bound makes it NaN
        or +-inf). g > 1e-12 means crossing bounds. Only when a test fails are the arrays
        examined one by one to name the culprit.
        """
        m, n = self.jacobian.shape if self.jacobian.ndim == 2 else (-1, -1)
        if m < 1 or self.reference.shape != (m,):
            return f"bad shapes: J {self.jacobian.shape}, reference {self.reference.shape}"
        if self.lower.shape != (n,) or self.upper.shape != (n,) or self.repulsive.shape != (n,):
            for name in ("lower", "upper", "repulsive"):
                if getattr(self, name).shape != (n,):
                    return f"bad shape of {name}: {getattr(self, name).shape}, expected ({n},)"
        gap = (self.lower - self.upper).max()
        # the short vectors summed in Python (numpy's reduction costs 4x more on so few; the same NaN and inf)
        if not math.isfinite(self.jacobian.sum() + sum(self.reference.tolist()) + sum(self.repulsive.tolist()) + gap):
            for name in ("jacobian", "reference", "lower", "upper", "repulsive"):
                if not np.all(np.isfinite(getattr(self, name))):
                    return f"non-finite values in {name}"
        if self.inequality_jacobian is not None or self.inequality_bound is not None \
                or self.equality_weights is not None or self.inequality_weights is not None \
                or self.limit_rows is not None or self.limit_bound is not None or self.limit_deferred is not None \
                or self.secondary_jacobian is not None or self.secondary_reference is not None:
            optional = self._problem_with_optional_rows(m, n)
            if optional:
                return optional
        if gap > 1e-12:
            i = int(np.argmax(self.lower - self.upper))
            return f"velocity bounds cross at joint {i}: lower {self.lower[i]:.4g} > upper {self.upper[i]:.4g} (joint outside its position range)"
        return ""

    def _problem_with_optional_rows(self, m: int, n: int) -> str:
        """Shapes and finiteness of the optional inequality rows and weights ('' when usable)."""
        a, h = self.inequality_jacobian, self.inequality_bound
        if (a is None) != (h is None):
            return "inequality_jacobian and inequality_bound must be given together"
        m_ie = 0
        if a is not None and h is not None:
            m_ie = a.shape[0] if a.ndim == 2 else -1
            if a.shape != (m_ie, n) or h.shape != (m_ie,):
                return f"bad shapes: inequality_jacobian {a.shape}, inequality_bound {h.shape}"
            if not math.isfinite(a.sum() + h.sum()):
                return "non-finite values in the inequality rows"
        a, h = self.secondary_jacobian, self.secondary_reference
        if (a is None) != (h is None):
            return "secondary_jacobian and secondary_reference must be given together"
        if a is not None and h is not None:
            m_2 = a.shape[0] if a.ndim == 2 else -1
            if m_2 < 1 or a.shape != (m_2, n) or h.shape != (m_2,):
                return f"bad shapes: secondary_jacobian {a.shape}, secondary_reference {h.shape}"
            if not math.isfinite(a.sum() + h.sum()):
                return "non-finite values in the secondary task (second priority)"
        a, h = self.limit_rows, self.limit_bound
        if a is None and self.limit_deferred is not None:  # checked without building the rows: their speed bound
            a = self.limit_deferred.speed
        if (a is None) != (h is None):
            return "limit_rows and limit_bound must be given together"
        if a is not None and h is not None:
            m_l = a.shape[0] if a.ndim == 2 else -1
            if a.shape != (m_l, n) or h.shape != (m_l,):
                return f"bad shapes: limit_rows {a.shape}, limit_bound {h.shape}"
            if not math.isfinite(a.sum() + h.sum()):
                return "non-finite values in the limit rows"
        for name, size in (("equality_weights", m), ("inequality_weights", m_ie)):
            w = getattr(self, name)
            if w is None:
                continue
            if w.shape != (size,):
                return f"bad shape of {name}: {w.shape}, expected ({size},)"
            if not math.isfinite(w.sum()) or w.min(initial=0.0) < 0:
                return f"{name} must be finite and >= 0"
        return ""
