"""The plane of flight as the viewer draws it: a top-down 2-D view spanned by the position states (roles).

Rerun's 2-D views point their y axis down, so the second position (the vertical one, or north) is drawn negated:
up is up on the screen. A plant without position roles has no plane and no scene.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from workbench.errors import DataError

__all__ = ["Plane", "plane_of"]


@dataclass(frozen=True)
class Plane:
    """State indices of the plane of flight: ``across`` (screen right), ``up`` (screen up), the heading angle."""

    across: int
    up: int
    heading: int | None = None

    def view(self, x: np.ndarray) -> np.ndarray:
        """Screen coordinates (N, 2) of states ``x`` (N, n): across right, up drawn up (negated for rerun)."""
        x = np.atleast_2d(np.asarray(x, dtype=float))
        return np.column_stack([x[:, self.across], -x[:, self.up]])

    def angle(self, x: np.ndarray) -> np.ndarray:
        """The vehicle's rotation in the view (rad): the heading state, zero without one.

        A positive bank tilts the thrust toward +across (ẍ = g φ in the paper's plant); on rerun's y-down
        screen that is a positive rotation about the view's z axis.
        """
        x = np.atleast_2d(np.asarray(x, dtype=float))
        return x[:, self.heading] if self.heading is not None else np.zeros(len(x))

    def bounds(self, points: Iterable[np.ndarray], margin: float = 0.08) -> tuple[list[float], list[float]]:
        """Visual bounds (x_range, y_range) fitting every screen point with ``margin`` of the larger extent."""
        pts = np.concatenate([np.atleast_2d(p) for p in points if np.size(p)])
        pts = pts[np.isfinite(pts).all(axis=1)]
        if not len(pts):
            return [-1.0, 1.0], [-1.0, 1.0]
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        pad = margin * max(float(np.max(hi - lo)), 1e-6)
        return [float(lo[0] - pad), float(hi[0] + pad)], [float(lo[1] - pad), float(hi[1] + pad)]


def plane_of(roles: Any, state_names: Any) -> Plane | None:
    """The plane of flight from vehicle roles (:class:`workbench.data.roles.Roles`), ``None`` without two positions."""
    if not roles:
        return None
    try:
        resolved = roles.resolve(list(state_names))
    except DataError:  # roles of other names (e.g. a model's plant for unnamed states): no scene, plots only
        return None
    plane = resolved.plane
    if plane is None:
        return None
    return Plane(across=plane[0], up=plane[1], heading=resolved.heading)
