"""Why an episode ends: the failure terminations of a physics state (FAIL_REASONS) and the step's Ends."""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jp

from foottof.envs.stuck_probe import foot_stuck
from foottof.envs.task_spec import TaskSpec
from foottof.robot import kinematics
from foottof.robot.model import (
    BASE_SPHERE_CENTRES_M,
    BASE_SPHERE_RADIUS_M,
    KNEE_SPHERE_RADIUS_M,
)

# Why an episode failed (AnymalToF.fail_reasons; any of them ends it, and so does divergence):
# the base (or a knee, with env.knee_contact_terminates) touches the terrain, the base fell below
# the pit floor + env.fall_height_above_floor_m, a foot went below env.foot_fall_z_m, a foot is
# stuck in a gap (env.foot_stuck_depth_m), the base tilted beyond env.max_tilt_deg.
FAIL_REASONS = ("body_contact", "fell", "foot_deep", "foot_stuck", "flipped")


class Ends(NamedTuple):
    """How the step ended the episode, if it did."""

    failed: jax.Array  # () bool: failure termination (incl. divergence)
    truncated: jax.Array  # () bool: the deadline, without failure
    done: jax.Array  # () bool
    knee_contact: jax.Array  # (4,) float
    stuck: jax.Array  # () bool: a foot went into a gap (its own reason, part of failed)


def fail_reasons(spec: TaskSpec, hfield, d, gravity, fk: kinematics.FootKinematics):
    """Which failure terminations hold in the physics state ``d`` after a step.

    The base touches the terrain (knee contact too if ``env.knee_contact_terminates``), the base
    fell into a gap, a foot went below ``env.foot_fall_z_m``, a foot is stuck in a gap, bad
    orientation.

    Args:
      spec: the task's settings; hfield: the terrain (``height_at``, ``z_floor_m``).
      d: the physics state (``qpos``); gravity: (3,) projected gravity (base frame).
      fk: the world foot kinematics of ``d`` (feet and knees).

    Returns:
      ({reason: () bool} in FAIL_REASONS order, (4,) bool knee contacts).
    """
    base_pos, base_quat = d.qpos[0:3], d.qpos[3:7]
    centres = kinematics.base_to_world(
        jp.asarray(BASE_SPHERE_CENTRES_M, jp.float32), base_pos, base_quat
    )
    base_clear = centres[:, 2] - hfield.height_at(centres[:, :2]) - BASE_SPHERE_RADIUS_M
    knees = fk.knee_pos
    knee_clear = knees[:, 2] - hfield.height_at(knees[:, :2]) - KNEE_SPHERE_RADIUS_M
    knee_contact = knee_clear < spec.body_contact_margin_m
    body_contact = jp.min(base_clear) < spec.body_contact_margin_m
    if spec.knee_contact_terminates:
        body_contact = body_contact | jp.any(knee_contact)
    fell = base_pos[2] < hfield.z_floor_m + spec.fall_height_above_floor_m
    foot_deep = jp.min(fk.foot_pos[:, 2]) < spec.foot_fall_z_m
    stuck = jp.zeros((), bool)
    if spec.foot_stuck_depth_m > 0:
        stuck = jp.any(foot_stuck(fk.foot_pos, hfield.height_at, spec.foot_stuck_depth_m))
    flipped = gravity[2] > -math.cos(math.radians(spec.max_tilt_deg))
    reasons = dict(zip(FAIL_REASONS, (body_contact, fell, foot_deep, stuck, flipped), strict=True))
    return reasons, knee_contact


def failed(spec: TaskSpec, hfield, d, gravity, fk: kinematics.FootKinematics):
    """(failure: any of :func:`fail_reasons`, (4,) float knee contacts (1.0 where a knee
    touches), whether a foot is stuck: ``foot_stuck``, its own reason)."""
    reasons, knee_contact = fail_reasons(spec, hfield, d, gravity, fk)
    any_failed = functools.reduce(jp.logical_or, reasons.values())
    return any_failed, knee_contact.astype(jp.float32), reasons["foot_stuck"]


def ends(failed_now, knee_contact, stuck, step, episode_steps: int, diverged) -> Ends:
    """The step's Ends: failed (a failure termination or a diverged simulation), truncated (the
    deadline ``step >= episode_steps`` without failure), done (either)."""
    any_failed = failed_now | diverged
    truncated = (step >= episode_steps) & ~any_failed
    return Ends(any_failed, truncated, any_failed | truncated, knee_contact, stuck)
