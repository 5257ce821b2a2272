"""Compiled kernel: per-pose sums of landmark information ``sum J^T S^-1 J`` (numba).

This is the inner loop of :func:`markerplace.plan.score.localizability.pose_information`, the planner's
hot path (every feasible pose x up to ~1000 landmarks). The math is the closed form documented
in :mod:`markerplace.plan.score.localizability` (and tested against GTSAM there); this module only makes
it fast: one pass over the landmarks of each pose, the 2x6 whitened Jacobian kept in registers
and the 21 distinct entries of the symmetric 6x6 sum accumulated as scalars, poses spread over
threads with ``numba.prange``.

The kernel is compiled on first use and cached on disk by numba (``cache=True``: in
``NUMBA_CACHE_DIR``, which importing markerplace points at ``$MARKERPLACE_CACHE/numba``,
:mod:`markerplace.runtime.cache_home`), so later processes start without compiling. Fast-math allows
reassociation (vectorized sums) but not FMA contraction: with contraction the freshly compiled
kernel and the one loaded from the cache gave results differing in the last bits, so the first
``plan`` after an install did not reproduce later ones bit for bit.
"""

from __future__ import annotations

import numba
import numpy as np

# Open3D ships an older libtbb than numba's TBB layer accepts; asking for OpenMP first avoids
# numba's attempt (and its warning). Numba falls back to its own workqueue if OpenMP is absent.
numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]


@numba.njit(parallel=True, cache=True, fastmath={'reassoc', 'nsz', 'arcp'}, boundscheck=False)
def landmark_information_sums(R: np.ndarray, c_off: np.ndarray, pts: np.ndarray,
                              starts: np.ndarray, var: np.ndarray, fx: float, fy: float,
                              sig2: float, max_r2: float, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """Write ``out[n] = sum_{i in pose n} A_i^T A_i`` (whitened landmark information).

    Args:
        R: (N, 3, 3) float64 camera rotations ``world_from_cam[:, :3, :3]``.
        c_off: (N, 3) float64 ``-R^T t``, so that ``p_c = R^T p_w + c_off`` (camera frame, m).
        pts: (P, 3) float64 landmark positions, world metres, grouped by pose.
        starts: (N + 1,) int64: the landmarks of pose ``n`` are ``pts[starts[n]:starts[n+1]]``.
        var: (P,) float64 isotropic landmark variance per axis, m^2 (0 = known point).
        fx, fy: focal lengths, pixels.
        sig2: pixel noise variance, pixel^2.
        max_r2: squared range limit, m^2; farther landmarks, those with z <= 1e-6 m and
            non-finite ones are skipped.
        out: (N, 6, 6) float64, overwritten; tangent order (omega, nu), 1/rad^2 and 1/m^2.
    """
    N = R.shape[0]
    for n in numba.prange(N):
        r00 = R[n, 0, 0]
        r01 = R[n, 0, 1]
        r02 = R[n, 0, 2]
        r10 = R[n, 1, 0]
        r11 = R[n, 1, 1]
        r12 = R[n, 1, 2]
        r20 = R[n, 2, 0]
        r21 = R[n, 2, 1]
        r22 = R[n, 2, 2]
        c0 = c_off[n, 0]
        c1 = c_off[n, 1]
        c2 = c_off[n, 2]
        m00 = m01 = m02 = m03 = m04 = m05 = 0.0
        m11 = m12 = m13 = m14 = m15 = 0.0
        m22 = m23 = m24 = m25 = 0.0
        m33 = m34 = m35 = 0.0
        m44 = m45 = 0.0
        m55 = 0.0
        for i in range(starts[n], starts[n + 1]):
            px = pts[i, 0]
            py = pts[i, 1]
            pz = pts[i, 2]
            # p_c = R^T p + c_off
            x = r00 * px + r10 * py + r20 * pz + c0
            y = r01 * px + r11 * py + r21 * pz + c1
            z = r02 * px + r12 * py + r22 * pz + c2
            if not (z > 1e-6 and x * x + y * y + z * z <= max_r2):  # also drops NaN points
                continue
            rho = 1.0 / z
            u = x * rho
            v = y * rho
            uv = u * v
            uu1 = u * u + 1.0
            vv1 = v * v + 1.0
            # S = sig2 I + var rho^2 F [[1+u^2, uv], [uv, 1+v^2]] F = L L^T (Cholesky)
            s = rho * rho * var[i]
            l11 = np.sqrt(s * (fx * fx) * uu1 + sig2)
            l21 = s * (fx * fy) * uv / l11
            l22 = np.sqrt(s * (fy * fy) * vv1 + sig2 - l21 * l21)
            a = fx / l11
            b = fy / l22
            c = a * l21 / l22
            # rows of A = L^-1 J, J = F [j1; j2] with j1 = [uv, -(1+u^2), v, -rho, 0, u rho]
            # and j2 = [1+v^2, -uv, -u, 0, -rho, v rho]
            g10 = a * uv
            g11 = -a * uu1
            g12 = a * v
            g13 = -a * rho
            g15 = a * rho * u
            g20 = b * vv1 - c * uv
            g21 = c * uu1 - b * uv
            g22 = -(b * u + c * v)
            g23 = c * rho
            g24 = -b * rho
            g25 = (b * v - c * u) * rho
            m00 += g10 * g10 + g20 * g20
            m01 += g10 * g11 + g20 * g21
            m02 += g10 * g12 + g20 * g22
            m03 += g10 * g13 + g20 * g23
            m04 += g20 * g24
            m05 += g10 * g15 + g20 * g25
            m11 += g11 * g11 + g21 * g21
            m12 += g11 * g12 + g21 * g22
            m13 += g11 * g13 + g21 * g23
            m14 += g21 * g24
            m15 += g11 * g15 + g21 * g25
            m22 += g12 * g12 + g22 * g22
            m23 += g12 * g13 + g22 * g23
            m24 += g22 * g24
            m25 += g12 * g15 + g22 * g25
            m33 += g13 * g13 + g23 * g23
            m34 += g23 * g24
            m35 += g13 * g15 + g23 * g25
            m44 += g24 * g24
            m45 += g24 * g25
            m55 += g15 * g15 + g25 * g25
        o = out[n]
        o[0, 0] = m00
        o[1, 1] = m11
        o[2, 2] = m22
        o[3, 3] = m33
        o[4, 4] = m44
        o[5, 5] = m55
        o[0, 1] = o[1, 0] = m01
        o[0, 2] = o[2, 0] = m02
        o[0, 3] = o[3, 0] = m03
        o[0, 4] = o[4, 0] = m04
        o[0, 5] = o[5, 0] = m05
        o[1, 2] = o[2, 1] = m12
        o[1, 3] = o[3, 1] = m13
        o[1, 4] = o[4, 1] = m14
        o[1, 5] = o[5, 1] = m15
        o[2, 3] = o[3, 2] = m23
        o[2, 4] = o[4, 2] = m24
        o[2, 5] = o[5, 2] = m25
        o[3, 4] = o[4, 3] = m34
        o[3, 5] = o[5, 3] = m35
        o[4, 5] = o[5, 4] = m45
