"""Run configuration: model, solver and adaptivity parameters as frozen dataclasses.

Every parameter has a default (the paper's computational example where it gives one); a scene
states only what differs. Names are unique across the three groups so that ``--set eps=0.025``
and sweep grids can address them without a prefix.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "ModelParameters",
    "SolverParameters",
    "AdaptivityParameters",
    "Parameters",
    "ParameterError",
]


class ParameterError(ValueError):
    """A parameter has a wrong name, type or value."""


@dataclass(frozen=True)
class ModelParameters:
    """Ambrosio–Tortorelli model (paper, eq. 6–7 and Section 1.2).

    Attributes
    ----------
    eps
        Regularisation length ε.
    eta
        Residual stiffness η, 0 ≤ η ≪ ε.
    crtol
        Crack-set tolerance: CR(t_k) = {v(t_{k-1}) < crtol}.
    """

    eps: float = 0.05
    eta: float = 1e-5
    crtol: float = 1e-4

    @property
    def alpha(self) -> float:
        """α = 1/(4ε)."""
        return 1 / (4 * self.eps)

    def check(self) -> None:
        """Raise :class:`ParameterError` naming the first invalid value."""
        if not self.eps > 0:
            raise ParameterError(f"eps must be positive, got eps={self.eps}")
        if not self.eta >= 0:
            raise ParameterError(f"eta must be non-negative, got eta={self.eta}")
        if not self.eta < self.eps:
            raise ParameterError(
                f"eta must be smaller than eps, got eta={self.eta}, eps={self.eps}"
            )
        if not 0 < self.crtol < 1:
            raise ParameterError(f"crtol must lie in (0, 1), got crtol={self.crtol}")


@dataclass(frozen=True)
class SolverParameters:
    """Alternating minimisation (paper, Algorithm 1).

    Attributes
    ----------
    am_tol
        Stop when ‖v^n − v^{n−1}‖_∞ < am_tol.
    am_max_iter
        Iteration limit per load step.
    """

    am_tol: float = 1e-3
    am_max_iter: int = 1000

    def check(self) -> None:
        """Raise :class:`ParameterError` naming the first invalid value."""
        if not self.am_tol > 0:
            raise ParameterError(f"am_tol must be positive, got am_tol={self.am_tol}")
        if not self.am_max_iter >= 1:
            raise ParameterError(f"am_max_iter must be >= 1, got am_max_iter={self.am_max_iter}")


@dataclass(frozen=True)
class AdaptivityParameters:
    """Mesh: initial size and, later, refinement (paper, Algorithm 2).

    Attributes
    ----------
    maxh
        Initial mesh size.
    """

    maxh: float = 0.25

    def check(self) -> None:
        """Raise :class:`ParameterError` naming the first invalid value."""
        if not self.maxh > 0:
            raise ParameterError(f"maxh must be positive, got maxh={self.maxh}")


@dataclass(frozen=True)
class Parameters:
    """All parameters of a run, grouped; :meth:`replace` addresses them by bare name."""

    model: ModelParameters = field(default_factory=ModelParameters)
    solver: SolverParameters = field(default_factory=SolverParameters)
    adaptivity: AdaptivityParameters = field(default_factory=AdaptivityParameters)

    def _groups(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def names(self) -> dict[str, type]:
        """Return every parameter name with its type."""
        return {
            f.name: type(getattr(group, f.name))
            for group in self._groups().values()
            for f in dataclasses.fields(group)
        }

    def replace(self, **values: Any) -> Parameters:
        """Return a copy with the named parameters changed, converting strings to their type.

        Raises
        ------
        ParameterError
            For an unknown name or a value that does not convert to the parameter's type.
        """
        names = self.names()
        groups = self._groups()
        changes: dict[str, dict[str, Any]] = {}
        for name, value in values.items():
            if name not in names:
                known = ", ".join(sorted(names))
                raise ParameterError(f"unknown parameter '{name}' (known: {known})")
            kind = names[name]
            try:
                converted = kind(value) if not isinstance(value, kind) else value
                if kind is int and isinstance(value, float) and value != int(value):
                    raise ValueError
            except (TypeError, ValueError):
                raise ParameterError(
                    f"parameter '{name}' needs a {kind.__name__}, got {value!r}"
                ) from None
            group = next(g for g, obj in groups.items() if hasattr(obj, name))
            changes.setdefault(group, {})[name] = converted
        new = {g: dataclasses.replace(groups[g], **c) for g, c in changes.items()}
        result = dataclasses.replace(self, **new)
        result.check()
        return result

    def check(self) -> None:
        """Check every group; raise :class:`ParameterError` naming the first invalid value."""
        for group in self._groups().values():
            group.check()

    def flat(self) -> dict[str, Any]:
        """Return all parameters as one flat dictionary (for summaries and sweep tables)."""
        return {
            f.name: getattr(group, f.name)
            for group in self._groups().values()
            for f in dataclasses.fields(group)
        }
