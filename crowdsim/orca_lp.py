"""ORCA's linear programs, after RVO2's ``linearProgram1/2/3`` (``crowdsim.orca`` builds the half-planes and
calls them per agent). They run in plain Python floats on lists of line points ``px, py`` and unit directions
``dx, dy``: sequential by nature, and faster than numpy scalars for a handful of lines. The same arithmetic,
float64 for RVO2's float32, and the same ``RVO_EPSILON`` for (almost) parallel lines.

A velocity ``(x, y)`` satisfies line ``i`` when ``dx[i] (py[i] - y) - dy[i] (px[i] - x) <= 0`` (it lies on
the line's left); the programs keep to the disc of radius ``radius`` (the agent's maximum speed).
"""

from __future__ import annotations

import math
from typing import Final

RVO_EPSILON: Final[float] = 1e-5  # RVO2's Definitions.h: tolerance for (almost) parallel lines


def lp1(px, py, dx, dy, no, radius, optx, opty, direction_opt):
    """RVO2's linearProgram1: optimum on line ``no`` within the disc and lines ``0..no-1``, or None."""
    dot = px[no] * dx[no] + py[no] * dy[no]
    discriminant = dot * dot + radius * radius - (px[no] * px[no] + py[no] * py[no])
    if discriminant < 0.0:
        return None  # the max-speed disc lies entirely outside line ``no``
    sq = math.sqrt(discriminant)
    t_left = -dot - sq
    t_right = -dot + sq
    dxn, dyn, pxn, pyn = dx[no], dy[no], px[no], py[no]
    for i in range(no):
        denominator = dxn * dy[i] - dyn * dx[i]
        numerator = dx[i] * (pyn - py[i]) - dy[i] * (pxn - px[i])
        if abs(denominator) <= RVO_EPSILON:
            if numerator < 0.0:
                return None  # (almost) parallel and line ``no`` lies outside line i
            continue
        t = numerator / denominator
        if denominator >= 0.0:
            t_right = min(t_right, t)
        else:
            t_left = max(t_left, t)
        if t_left > t_right:
            return None
    if direction_opt:
        t = t_right if optx * dxn + opty * dyn > 0.0 else t_left
    else:
        t = dxn * (optx - pxn) + dyn * (opty - pyn)
        t = t_left if t < t_left else (t_right if t > t_right else t)
    return pxn + t * dxn, pyn + t * dyn


def lp2(px, py, dx, dy, radius, optx, opty, direction_opt):
    """RVO2's linearProgram2. Returns ``(index of the first infeasible line or len(lines), x, y)``."""
    if direction_opt:
        rx, ry = optx * radius, opty * radius  # optx, opty is a unit direction here
    else:
        norm_sq = optx * optx + opty * opty
        if norm_sq > radius * radius:
            scale = radius / math.sqrt(norm_sq)
            rx, ry = optx * scale, opty * scale
        else:
            rx, ry = optx, opty
    for i in range(len(px)):
        if dx[i] * (py[i] - ry) - dy[i] * (px[i] - rx) > 0.0:
            new = lp1(px, py, dx, dy, i, radius, optx, opty, direction_opt)
            if new is None:
                return i, rx, ry
            rx, ry = new
    return len(px), rx, ry


def lp3(px, py, dx, dy, begin, radius, rx, ry):
    """RVO2's linearProgram3 (no obstacle lines): the velocity minimising the largest line penetration."""
    distance = 0.0
    for i in range(begin, len(px)):
        if dx[i] * (py[i] - ry) - dy[i] * (px[i] - rx) > distance:
            qpx, qpy, qdx, qdy = [], [], [], []
            for j in range(i):
                determinant = dx[i] * dy[j] - dy[i] * dx[j]
                if abs(determinant) <= RVO_EPSILON:
                    if dx[i] * dx[j] + dy[i] * dy[j] > 0.0:
                        continue  # parallel, same direction: line j adds nothing
                    ox, oy = 0.5 * (px[i] + px[j]), 0.5 * (py[i] + py[j])
                else:
                    f = (dx[j] * (py[i] - py[j]) - dy[j] * (px[i] - px[j])) / determinant
                    ox, oy = px[i] + f * dx[i], py[i] + f * dy[i]
                ex, ey = dx[j] - dx[i], dy[j] - dy[i]
                norm = math.sqrt(ex * ex + ey * ey)
                qpx.append(ox)
                qpy.append(oy)
                qdx.append(ex / norm)
                qdy.append(ey / norm)
            fail, nx, ny = lp2(qpx, qpy, qdx, qdy, radius, -dy[i], dx[i], True)
            # A failure here is floating-point noise (the current result is feasible by construction):
            # keep the current result.
            if fail >= len(qpx):
                rx, ry = nx, ny
            distance = dx[i] * (py[i] - ry) - dy[i] * (px[i] - rx)
    return rx, ry
