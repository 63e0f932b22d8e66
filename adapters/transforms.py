"""Named channel transforms: the few conversions a mapping cannot express with scale, offset and sign.

Each transform takes the source field's columns (one column, or four for a quaternion) and returns one
channel; its inverse is what the writers use to put a demonstration back into a log's native fields, so a
written log maps back onto the same channel values.

========================  =========  ======================================================================
name                      columns    channel
========================  =========  ======================================================================
``identity``              1          the field as it is
``ned_up``                1          ``-v``: NED's down-positive z (or its rate) as the paper's up-positive y
``pwm``                   1          RC pulse width ``pwm_min``–``pwm_max`` µs (default 1000–2000) → [−1, 1],
                                     clipped (sticks beyond their calibrated end points saturate)
``quaternion_roll``       4          roll of the unit quaternion ``[w, x, y, z]`` (rad, ZYX Euler angles)
``quaternion_pitch``      4          pitch, likewise
``quaternion_yaw``        4          yaw, likewise
``euler_tilt_east``       3          ``roll, pitch, yaw`` (rad, ZYX) → the thrust axis's tilt from the vertical
                                     in the east–up plane (rad, positive toward east): the angle whose
                                     tangent times g is the east acceleration of a hovering multirotor,
                                     whatever its heading
``euler_tilt_north``      3          ``roll, pitch, yaw`` (rad) → the thrust axis's tilt in the north–up plane
                                     (rad, positive toward north): what accelerates a multirotor north
``euler_deg_tilt_east``   3          ``euler_tilt_east`` of angles in degrees (DataFlash ``ATT`` / ``EKF1``
                                     ``Roll, Pitch, Yaw``)
``heading_right``         3          ``yaw, north, east`` → the vector's component along the vehicle's
                                     right (its heading frame's lateral axis): what its roll accelerates;
                                     the yaw in degrees, or ``yaw_scale`` radians per unit (1: radians);
                                     for a velocity (its position: ``integrate``, below)
``heading_forward``       3          ``yaw, north, east`` → the component along its heading: what its
                                     pitch accelerates (forward is nose-down pitch, negative); likewise
``euler_tilt_east_rate``  5          ``roll, pitch, yaw, rollspeed, pitchspeed`` (rad, rad/s body rates) → the
                                     rate of ``euler_tilt_east`` (rad/s); yaw rate does not move the axis
========================  =========  ======================================================================

A vehicle that turns while it flies (the real ArduCopter flight in ``../shared/external`` yaws through several
full turns) leans east with its roll only when it points north: a planar east–up model needs the tilt, not
the body roll, or the east velocity's response to the angle comes out a fraction of g·dt.

``heading_right`` and ``heading_forward`` are for velocities. A position rotated into the heading frame moves
with the turn as well as with the flight (its rate is ``v_right − ψ̇·p_forward``, not ``v_right``), which no
plant's kinematic row ``p[k+1] = p[k] + dt·v[k]`` holds: a mapping declares that position as its velocity's
running integral instead, ``x = { integrate = "xdot" }`` (:mod:`adapters.mapping`; a transform sees one sample at
a time and no segment, so the integral is the pipeline's, :func:`adapters.pipeline.integrate`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["Transform", "TRANSFORMS", "get_transform"]


@dataclass(frozen=True)
class Transform:
    """A named conversion from ``n_columns`` field columns to one channel, with its inverse."""

    name: str
    n_columns: int
    forward: Callable[[np.ndarray, Mapping[str, Any]], np.ndarray]
    inverse: Callable[[np.ndarray, Mapping[str, Any]], np.ndarray]
    params: tuple[str, ...] = ()


def _pwm_range(p: Mapping[str, Any]) -> tuple[float, float]:
    return float(p.get("pwm_min", 1000.0)), float(p.get("pwm_max", 2000.0))


def _pwm(v: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    lo, hi = _pwm_range(p)
    return np.clip(2.0 * (v[:, 0] - lo) / (hi - lo) - 1.0, -1.0, 1.0)


def _pwm_inv(u: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    lo, hi = _pwm_range(p)
    return (lo + (np.clip(u, -1.0, 1.0) + 1.0) * 0.5 * (hi - lo))[:, None]


def _roll(q: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    w, x, y, z = q.T
    return np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))


def _pitch(q: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    w, x, y, z = q.T
    return np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))


def _yaw(q: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    w, x, y, z = q.T
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _rotation(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Body → NED rotation matrices ``Rz(yaw) Ry(pitch) Rx(roll)``, shape (N, 3, 3)."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    return np.stack([
        np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
        np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
        np.stack([-sp, cp * sr, cp * cr], -1),
    ], -2)


def _tilt_east(v: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    R = _rotation(v[:, 0], v[:, 1], v[:, 2])
    east, up = -R[:, 1, 2], R[:, 2, 2]  # thrust along −z_body: its east and up (−down) components
    return np.arctan2(east, up)


def _tilt_east_rate(v: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    R = _rotation(v[:, 0], v[:, 1], v[:, 2])
    # d/dt (−R e3) = −R (ω × e3) = −R [q, −p, 0]: only roll and pitch rates move the thrust axis
    w = np.stack([v[:, 4], -v[:, 3], np.zeros(len(v))], -1)
    d = -np.einsum("nij,nj->ni", R, w)
    east, up, d_east, d_up = -R[:, 1, 2], R[:, 2, 2], d[:, 1], -d[:, 2]
    return (up * d_east - east * d_up) / (east**2 + up**2)


def _tilt_north(v: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    R = _rotation(v[:, 0], v[:, 1], v[:, 2])
    north, up = -R[:, 0, 2], R[:, 2, 2]  # thrust along −z_body: its north and up (−down) components
    return np.arctan2(north, up)


def _tilt_north_inv(angle: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    z = np.zeros_like(angle)
    return np.column_stack([z, -angle, z])  # heading north, level in roll: nose-down pitch tilts the thrust north


def _tilt_east_deg(v: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    return _tilt_east(np.deg2rad(v), p)


def _tilt_deg_inv(angle: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    return np.rad2deg(_tilt_inv(angle, p))


def _yaw_rad(v: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    """The heading column in radians: ``yaw_scale`` radians per logged unit (default a degree, as ArduPilot's
    ``EKF1.Yaw`` logs it; 1 for PX4's ``vehicle_local_position.heading``, logged in radians)."""
    return v[:, 0] * float(p.get("yaw_scale", np.pi / 180.0))


def _heading_right(v: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    yaw = _yaw_rad(v, p)
    return -np.sin(yaw) * v[:, 1] + np.cos(yaw) * v[:, 2]


def _heading_forward(v: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    yaw = _yaw_rad(v, p)
    return np.cos(yaw) * v[:, 1] + np.sin(yaw) * v[:, 2]


def _heading_right_inv(value: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    z = np.zeros_like(value)
    return np.column_stack([z, z, value])  # heading north: right is east


def _heading_forward_inv(value: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    z = np.zeros_like(value)
    return np.column_stack([z, value, z])  # heading north: forward is north


def _tilt_inv(angle: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    return np.column_stack([angle, np.zeros_like(angle), np.zeros_like(angle)])  # heading north: tilt = roll


def _tilt_rate_inv(rate: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
    z = np.zeros_like(rate)
    return np.column_stack([z, z, z, rate, z])  # level, north: the rate is the roll rate


def _axis_quaternion(axis: int) -> Callable[[np.ndarray, Mapping[str, Any]], np.ndarray]:
    def inverse(angle: np.ndarray, p: Mapping[str, Any]) -> np.ndarray:
        q = np.zeros((angle.size, 4))
        q[:, 0] = np.cos(angle / 2.0)
        q[:, axis] = np.sin(angle / 2.0)
        return q

    return inverse


TRANSFORMS: dict[str, Transform] = {
    t.name: t
    for t in (
        Transform("identity", 1, lambda v, p: v[:, 0], lambda u, p: u[:, None]),
        Transform("ned_up", 1, lambda v, p: -v[:, 0], lambda u, p: -u[:, None]),
        Transform("pwm", 1, _pwm, _pwm_inv, ("pwm_min", "pwm_max")),
        Transform("quaternion_roll", 4, _roll, _axis_quaternion(1)),
        Transform("quaternion_pitch", 4, _pitch, _axis_quaternion(2)),
        Transform("quaternion_yaw", 4, _yaw, _axis_quaternion(3)),
        Transform("euler_tilt_east", 3, _tilt_east, _tilt_inv),
        Transform("euler_tilt_east_rate", 5, _tilt_east_rate, _tilt_rate_inv),
        Transform("euler_deg_tilt_east", 3, _tilt_east_deg, _tilt_deg_inv),
        Transform("euler_tilt_north", 3, _tilt_north, _tilt_north_inv),
        Transform("heading_right", 3, _heading_right, _heading_right_inv, ("yaw_scale",)),
        Transform("heading_forward", 3, _heading_forward, _heading_forward_inv, ("yaw_scale",)),
    )
}


def get_transform(name: str) -> Transform | None:
    return TRANSFORMS.get(name)
