"""The goal error as network input: what a goal-conditioned arm policy needs to cut within 1 cm and 0.2 rad.

A goal of GrapeHarvest is 9 numbers: the clamp-centre position (m), its approach axis and its pallet axis.
SB3's ``MultiInputPolicy`` feeds ``achieved_goal`` and ``desired_goal`` side by side, so the network must
learn to subtract them before it can act on the difference, at a 1 cm scale on inputs that span a metre.
:func:`goal_error_features` hands it the difference directly, at two scales, and the rotation that would
align the axes:

| features | count | meaning |
|---|---|---|
| ``(d - a)[:3] * POSITION_SCALE`` | 3 | position error, in units of 10 cm |
| ``clip((d - a)[:3] * FINE_POSITION_SCALE, -1, 1)`` | 3 | the same, saturating at 2 cm: gain for the last centimetres |
| ``a_z x d_z``, ``a_x x d_x`` | 6 | each axis's rotation toward the goal's (sine of the angle, along the turn axis) |
| the same ``* FINE_ROTATION_SCALE``, clipped to [-1, 1] | 6 | saturating at about 0.2 rad, the tolerance |
| ``a_z . d_z``, ``a_x . d_x`` | 2 | cosines: tell a small error from one past 90 degrees |

The features are computed inside the policy (a features extractor), not by an observation wrapper, because
HER relabels ``desired_goal`` after the observation is stored: a wrapper's goal error would then contradict
the relabelled goal. Only element-wise ``+``, ``-``, ``*``, ``minimum`` and ``maximum`` occur, in a fixed
order, so the numpy form is a function of its inputs alone on every CPU (see
:mod:`agri_training.learned.inference`); :mod:`agri_training.learned.extractors` is the torch form that
training uses.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Name of the features (and of the SB3 features extractor) in ``policy_kwargs.features_extractor_class``.
GOAL_ERROR = "GoalErrorExtractor"
#: Length of a goal: position (3), approach axis (3), pallet axis (3).
GOAL_LENGTH = 9
#: Number of features :func:`goal_error_features` appends.
N_GOAL_ERROR_FEATURES = 20
#: Position error scale (1/m): 10 cm -> 1.
POSITION_SCALE = 10.0
#: Fine position error scale (1/m): 2 cm -> 1, clipped there.
FINE_POSITION_SCALE = 50.0
#: Fine rotation scale: an axis 0.2 rad off -> about 1, clipped there.
FINE_ROTATION_SCALE = 5.0


def _cross(u: list[Any], v: list[Any]) -> list[Any]:
    return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]


def _dot(u: list[Any], v: list[Any]) -> Any:
    return (u[0] * v[0] + u[1] * v[1]) + u[2] * v[2]


def goal_error_columns(achieved: list[Any], desired: list[Any], clip: Any) -> list[Any]:
    """The 20 feature columns from the 9 columns of each goal (numpy arrays or torch tensors alike).

    Args:
        achieved: The achieved goal's 9 columns, each of shape (batch,).
        desired: The desired goal's 9 columns.
        clip: ``clip(x)`` limiting a column to [-1, 1] (numpy's or torch's).
    """
    dp = [desired[i] - achieved[i] for i in range(3)]
    az, dz = achieved[3:6], desired[3:6]
    ax, dx = achieved[6:9], desired[6:9]
    turn_z, turn_x = _cross(az, dz), _cross(ax, dx)
    return (
        [x * POSITION_SCALE for x in dp]
        + [clip(x * FINE_POSITION_SCALE) for x in dp]
        + turn_z
        + turn_x
        + [clip(x * FINE_ROTATION_SCALE) for x in turn_z + turn_x]
        + [_dot(az, dz), _dot(ax, dx)]
    )


def goal_error_features(achieved: np.ndarray, desired: np.ndarray) -> np.ndarray:
    """The goal-error features of batches of goals (float64 arrays of shape (batch, 9)): shape (batch, 20)."""
    a = np.asarray(achieved, dtype=np.float64)
    d = np.asarray(desired, dtype=np.float64)
    if a.shape[-1] != GOAL_LENGTH or d.shape != a.shape:
        raise ValueError(f"goals must have shape (batch, {GOAL_LENGTH}), got {a.shape} and {d.shape}")
    columns = goal_error_columns(
        [a[:, i] for i in range(GOAL_LENGTH)],
        [d[:, i] for i in range(GOAL_LENGTH)],
        lambda x: np.minimum(np.maximum(x, -1.0), 1.0),
    )
    return np.stack(columns, axis=1)
