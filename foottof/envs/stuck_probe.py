"""The stuck-foot probe: whether a foot went into a gap (a termination, and the failure analysis)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jp

# Stuck-foot probe: the terrain within this radius of a foot centre (the centre and 8 points on
# the circle) is what the foot is compared against; one cell (4 cm) and a margin, so that the tops
# beside a one-vertex notch are in reach [m].
STUCK_PROBE_RADIUS_M = 0.05
# A gap, not a step: the probed terrain spans more than this (pits lie >= 0.8 m below the stone
# tops; stairs, boxes and drawn cracks span <= 0.3 m within 5 cm) [m].
STUCK_GAP_SPAN_M = 0.4
_STUCK_PROBE = tuple(
    (
        STUCK_PROBE_RADIUS_M * math.cos(k * math.pi / 4),
        STUCK_PROBE_RADIUS_M * math.sin(k * math.pi / 4),
    )
    for k in range(8)
) + ((0.0, 0.0),)


def _probe_top_bottom(foot_pos: jax.Array, height_at) -> tuple[jax.Array, jax.Array]:
    """(F,) highest and lowest terrain within STUCK_PROBE_RADIUS_M of each foot centre [m]."""
    offs = jp.asarray(_STUCK_PROBE, jp.float32)
    around = height_at(foot_pos[:, None, :2] + offs[None])  # (F, 9)
    return jp.max(around, axis=-1), jp.min(around, axis=-1)


def foot_stuck(foot_pos: jax.Array, height_at, depth_m: float) -> jax.Array:
    """(F,) bool: a foot went into a gap (wedged in a drawn notch, or falling through): its centre
    lies more than ``depth_m`` below the highest terrain within STUCK_PROBE_RADIUS_M, and that
    terrain spans a gap (more than STUCK_GAP_SPAN_M from its lowest to its highest point)."""
    top, bottom = _probe_top_bottom(foot_pos, height_at)
    return (foot_pos[:, 2] < top - depth_m) & (top - bottom > STUCK_GAP_SPAN_M)


def foot_gap_depth(foot_pos: jax.Array, height_at) -> jax.Array:
    """(F,) how far each foot centre lies below the highest terrain around it [m] where that
    terrain spans a gap, as foot_stuck measures it (-inf for a foot with no gap around it): which
    foot went in, for the failure analysis (foottof.eval.failures)."""
    top, bottom = _probe_top_bottom(foot_pos, height_at)
    return jp.where(top - bottom > STUCK_GAP_SPAN_M, top - foot_pos[:, 2], -jp.inf)
