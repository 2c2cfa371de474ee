"""Rotation-vector helpers for Cartesian TCP kinematics (UR poses are ``[x, y, z, rx, ry, rz]``)."""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "rotvec_to_matrix",
    "matrix_to_rotvec",
    "interpolate_rotvec",
    "integrate_rotvec",
    "limit_norm",
]


def rotvec_to_matrix(r: np.ndarray) -> np.ndarray:
    r = np.asarray(r, dtype=float)
    angle = float(np.linalg.norm(r))
    if angle < 1e-12:
        return np.eye(3)
    k = r / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * kx + (1.0 - np.cos(angle)) * (kx @ kx)


def matrix_to_rotvec(m: np.ndarray) -> np.ndarray:
    # atan2 of (sin, cos) keeps small angles exact, where arccos of the trace loses them.
    w = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    sin = float(np.linalg.norm(w)) / 2.0
    cos = (float(np.trace(m)) - 1.0) / 2.0
    angle = math.atan2(sin, cos)
    if angle < 1e-12:
        return w / 2.0
    if np.pi - angle < 1e-6:
        # Near pi the antisymmetric part vanishes; take the axis from the symmetric part.
        b = (m + np.eye(3)) / 2.0
        i = int(np.argmax(np.diag(b)))
        axis = b[:, i] / np.sqrt(b[i, i])
        if float(axis @ w) < 0:
            axis = -axis
        return axis * angle
    return w * (angle / (2.0 * sin))


def interpolate_rotvec(r0: np.ndarray, r1: np.ndarray, s: float) -> np.ndarray:
    """Orientation a fraction ``s`` of the way from ``r0`` to ``r1`` along the geodesic."""
    m0 = rotvec_to_matrix(r0)
    rel = matrix_to_rotvec(rotvec_to_matrix(r1) @ m0.T)
    return matrix_to_rotvec(rotvec_to_matrix(rel * s) @ m0)


def integrate_rotvec(r: np.ndarray, omega: np.ndarray, dt: float) -> np.ndarray:
    """Orientation after rotating at base-frame angular velocity ``omega`` for ``dt``."""
    if not np.any(omega):
        return np.asarray(r, dtype=float)
    return matrix_to_rotvec(rotvec_to_matrix(np.asarray(omega) * dt) @ rotvec_to_matrix(r))


def limit_norm(v: np.ndarray, limit: float) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v if n <= limit or n == 0.0 else v * (limit / n)
