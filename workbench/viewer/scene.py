"""The plane of flight as the viewer draws it: a top-down 2-D view spanned by the position states (roles).

Rerun's 2-D views point their y axis down, so the second position (the vertical one, or north) is drawn negated:
up is up on the screen. A plant without position roles has no plane and no scene.

What makes the plane read as a map: a scale bar of a round length (:func:`scale_bar`), a ground line where the
plane is vertical, the Monte Carlo band as a filled envelope (:func:`envelope`) instead of a ladder of outlined
boxes, and labels only where they do not run into each other (:func:`label_spots`).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
import rerun as rr

from workbench.errors import DataError
from workbench.viewer import style

__all__ = ["Plane", "envelope", "label_spots", "plane_of", "scale_bar"]


@dataclass(frozen=True)
class Plane:
    """State indices of the plane of flight: ``across`` (screen right), ``up`` (screen up), the heading angle."""

    across: int
    up: int
    heading: int | None = None
    vertical: bool = False  # whether ``up`` is the vertical axis (a side view with a ground), not north

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
    return Plane(across=plane[0], up=plane[1], heading=resolved.heading,
                 vertical=resolved.vertical is not None and resolved.position[resolved.vertical] == plane[1])


def envelope(lo: np.ndarray, hi: np.ndarray, color: tuple[int, int, int], label: str) -> rr.LineStrips2D:
    """A prediction band in the plane as one filled envelope under the lines.

    ``lo``, ``hi`` (N, 2) are the screen corners of each step's percentile box. Each box becomes a capsule along
    its long side (radius its short half-size, in scene units) and consecutive centres are joined by a strip as
    wide as the narrower box, so the boxes merge into one area; the color is opaque (a dark tint of the method's
    color) so overlaps do not darken, and the draw order puts it under every track and prediction.
    """
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    centre, half = (lo + hi) / 2, np.abs(hi - lo) / 2
    ok = np.isfinite(centre).all(axis=1) & np.isfinite(half).all(axis=1)
    centre, half = centre[ok], half[ok]
    strips, radii = [], []
    short = half.min(axis=1) if len(half) else np.zeros(0)
    for c, h, r in zip(centre, half, short, strict=True):
        axis = np.array([h[0] - r, 0.0]) if h[0] >= h[1] else np.array([0.0, h[1] - r])
        strips.append([c - axis, c + axis])
        radii.append(r)
    for k in range(len(centre) - 1):
        strips.append([centre[k], centre[k + 1]])
        radii.append(min(short[k], short[k + 1]))
    keep = [i for i, r in enumerate(radii) if r > 0]
    return rr.LineStrips2D([strips[i] for i in keep], radii=[float(radii[i]) for i in keep], colors=[color],
                           labels=[label], show_labels=False, draw_order=style.SCENE_ORDER["band"])


def nice_length(extent: float) -> float:
    """A round length (1, 2 or 5 × 10^k) near a fifth of ``extent``: the scale bar's."""
    if not extent > 0 or not np.isfinite(extent):
        return 1.0
    raw = extent / 5
    k = np.floor(np.log10(raw))
    for m in (5.0, 2.0, 1.0):
        if m * 10**k <= raw:
            return float(m * 10**k)
    return float(10**k)


def scale_bar(bounds: tuple[list[float], list[float]], unit: str) -> tuple[np.ndarray, str]:
    """The scale bar's two screen points (bottom left of ``bounds``) and its text, e.g. ``"5 m"``.

    Its length follows the larger extent: the view keeps the plane's aspect ratio, so a flight that barely moves
    across (a vertical descent) is shown as wide as it is tall, and a bar from the narrow extent was a speck.
    """
    (x_lo, x_hi), (y_lo, y_hi) = bounds
    length = nice_length(max(x_hi - x_lo, y_hi - y_lo))
    x0, y0 = x_lo + 0.04 * (x_hi - x_lo), y_hi - 0.05 * (y_hi - y_lo)  # rerun's y points down: y_hi is the bottom
    return np.array([[x0, y0], [x0 + length, y0]]), f"{length:g} {unit}".strip()


def label_spots(points: np.ndarray, min_distance: float) -> list[int]:
    """Indices of ``points`` to label so no two labels are closer than ``min_distance`` (first come, first kept)."""
    kept: list[int] = []
    pts = np.asarray(points, dtype=float)
    for i, p in enumerate(pts):
        if not np.isfinite(p).all():
            continue
        if all(np.hypot(*(p - pts[j])) >= min_distance for j in kept):
            kept.append(i)
    return kept
