"""Scripted state-machine experts for Reach, Push and PickAndPlace.

They replace the paper's TQC experts where a trained TQC agent is too costly (2-core CPU
profiles). Each expert reads its phase from the current observation alone (no hidden
state), so it recovers by itself when the object slips, and it is vectorised over envs.

panda-gym's end-effector control moves the gripper towards `ee + 0.05 * action[:3]` each step,
so every phase below picks a target point and the action is the clipped displacement to it.
Episodes end on success (object or gripper within 5 cm of the goal), so the sparse return is
minus the steps taken: the experts move at full speed on every axis (the action is clipped
per coordinate) wherever the exact path does not matter, and need not be exact at the goal.
Observation layouts (panda-gym 3.0.7):

* Reach: `ee_pos(3) ee_vel(3)`
* Push: `ee_pos(3) ee_vel(3) obj_pos(3) obj_rot(3) obj_vel(3) obj_angvel(3)`
* PickAndPlace: `ee_pos(3) ee_vel(3) finger_width(1) obj_pos(3) obj_rot(3) obj_vel(3) obj_angvel(3)`
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from gcdt.errors import GcdtError
from gcdt.policies.base import Policy

ACTION_SCALE = 0.05  # metres of end-effector displacement per unit action (panda-gym)
CUBE_HALF = 0.02  # half edge of the Push / PickAndPlace cube

# Push. The closed fingertips come down on a circle of radius PUSH_RUNUP around the cube, go
# round it at table height to the point behind it (seen from the goal), then push. Aligning
# before contact from a few cm back beats aiming straight at the contact point: a
# fast-moving gripper that touches the cube off-line launches it (it slides a long way).
PUSH_Z = 0.02  # fingertip height while pushing (cube centre height)
PUSH_RUNUP = 0.07  # approach circle radius: fingertips clear the cube's corners (2.8 cm) and lag
PUSH_STEP = 1.0  # radians per waypoint round the circle: each chord stays ~6 cm from the cube
PUSH_CONTACT = 0.045  # fingertip distance behind the cube centre that a push holds
PUSH_DEPTH = 0.06  # how far ahead of that point, along the cube-goal line, a push aims
PUSH_LATERAL = 0.015  # off the cube-goal line by more than this, re-approach instead of pushing
PUSH_ALIGNED = 0.005  # within this, push at full speed; slower in between, to steer first
PUSH_DIAGONAL = 0.5  # push speed across a cube diagonal, relative to along a face normal
PUSH_CLEARANCE = 0.04  # closer than this to the cube (not pushing): lift off it first
PUSH_LIFT_Z = 0.07  # height at which the fingers clear the cube

# PickAndPlace: the open fingers straddle the cube along y, so only a y offset makes a finger
# land on it; the gripper descends in one motion, staying above the cube (by PICK_CONE per
# metre of y offset, at most PICK_HOVER) while the y offset exceeds PICK_Y_FREE.
PICK_CONE = 2.0
PICK_HOVER = 0.05
PICK_Y_FREE = 0.008
PICK_CLOSE_XY = 0.008  # close the fingers once this close to the cube centre in x and in y ...
PICK_CLOSE_Z = 0.015  # ... and in z (still descending: closing takes a step)
PICK_HOLD = 0.03  # the cube counts as held while within this of the gripper in xy and in z
# Finger width (sum of both fingers) when closed on the 4 cm cube (up to its 5.7 cm diagonal,
# if it has turned), and open (8 cm); below MISSED_WIDTH the fingers closed on nothing.
GRASP_WIDTH = 0.06
MISSED_WIDTH = 0.03


def _clipped_action(target: np.ndarray, ee: np.ndarray) -> np.ndarray:
    """Displacement towards `target`, each coordinate clipped to [-1, 1].

    The fastest way to a point: every axis moves at full speed until it is there. The
    gripper lags its commanded target, so this also aims a little past the goal.
    """
    return np.clip((target - ee) / ACTION_SCALE, -1.0, 1.0)


def _to_action(target: np.ndarray, ee: np.ndarray, limit: np.ndarray | float = 1.0) -> np.ndarray:
    """Displacement towards `target`, its largest coordinate at most `limit` (per env).

    Scaling the whole vector (not clipping each coordinate) keeps the direction of motion,
    which matters when pushing: a clipped diagonal push turns into an axis-aligned one.
    """
    action = (target - ee) / ACTION_SCALE
    largest = np.max(np.abs(action), axis=-1, keepdims=True)
    scale = np.minimum(1.0, np.reshape(limit, (-1, 1)) / np.maximum(largest, 1e-9))
    return np.clip(action * scale, -1.0, 1.0)


def _reach(obs: Mapping[str, np.ndarray]) -> np.ndarray:
    ee = obs["observation"][:, 0:3]
    return _clipped_action(obs["desired_goal"], ee)


def _push(obs: Mapping[str, np.ndarray]) -> np.ndarray:
    o = obs["observation"]
    ee, obj, yaw, goal = o[:, 0:3], o[:, 6:9], o[:, 11], obs["desired_goal"]

    to_goal = goal[:, :2] - obj[:, :2]
    dist = np.linalg.norm(to_goal, axis=1, keepdims=True)
    direction = to_goal / np.maximum(dist, 1e-6)  # unit push direction, [n, 2]

    rel = ee[:, :2] - obj[:, :2]
    along = np.sum(rel * direction, axis=1)  # < 0 when the gripper is behind the cube
    lateral = np.linalg.norm(rel - along[:, None] * direction, axis=1)
    low = ee[:, 2] < PUSH_Z + 0.02
    pushing = low & (along < -CUBE_HALF) & (lateral < PUSH_LATERAL)
    # Too close to the cube to go round it without knocking it: lift off first.
    lifting = ~pushing & (np.linalg.norm(rel, axis=1) < PUSH_CLEARANCE) & (ee[:, 2] < PUSH_LIFT_Z)

    # Approach: step round the cube on the run-up circle, at most PUSH_STEP at a time,
    # towards the run-up point behind it; the descent happens on the way.
    angle = np.arctan2(rel[:, 1], rel[:, 0])
    heading = np.arctan2(direction[:, 1], direction[:, 0])
    to_go = (heading - angle) % (2 * np.pi) - np.pi  # to the angle behind the cube, heading + pi
    waypoint = angle + np.sign(to_go) * np.minimum(np.abs(to_go), PUSH_STEP)
    target = np.empty_like(ee)
    target[:, 0] = obj[:, 0] + PUSH_RUNUP * np.cos(waypoint)
    target[:, 1] = obj[:, 1] + PUSH_RUNUP * np.sin(waypoint)
    target[:, 2] = np.where(lifting, PUSH_LIFT_Z, PUSH_Z)
    target[:, :2] = np.where(lifting[:, None], ee[:, :2], target[:, :2])
    # Push: hold the point behind the cube on the cube-goal line (steering back onto it) and
    # move forward, the less the further off the line the gripper is.
    forward = np.clip((PUSH_LATERAL - lateral) / (PUSH_LATERAL - PUSH_ALIGNED), 0.0, 1.0)
    push_to = obj[:, :2] + (forward[:, None] * PUSH_DEPTH - PUSH_CONTACT) * direction
    target[:, :2] = np.where(pushing[:, None], push_to, target[:, :2])
    # A push across the cube's diagonal makes it slide sideways off the fingertips, and a
    # launched cube slides far: push at full speed only along a face normal.
    skew = np.abs((heading - yaw + np.pi / 4) % (np.pi / 2) - np.pi / 4)  # 0 to pi / 4
    speed = 1.0 - (1.0 - PUSH_DIAGONAL) * skew / (np.pi / 4)
    return np.where(pushing[:, None], _to_action(target, ee, speed), _clipped_action(target, ee))


def _pick_and_place(obs: Mapping[str, np.ndarray]) -> np.ndarray:
    o = obs["observation"]
    ee, width, obj, goal = o[:, 0:3], o[:, 6], o[:, 7:10], obs["desired_goal"]

    rel = obj - ee
    offset = np.abs(rel)
    horizontal = np.linalg.norm(rel[:, :2], axis=1)
    holding = (horizontal < PICK_HOLD) & (offset[:, 2] < PICK_HOLD)
    holding &= (width < GRASP_WIDTH) & (width > MISSED_WIDTH)  # closed on the cube
    at_cube = (offset[:, 0] < PICK_CLOSE_XY) & (offset[:, 1] < PICK_CLOSE_XY)
    at_cube &= offset[:, 2] < PICK_CLOSE_Z

    # Approach and descend in one motion, above the cube only while a finger could land on it.
    target = obj.copy()
    target[:, 2] += np.clip(PICK_CONE * (offset[:, 1] - PICK_Y_FREE), 0.0, PICK_HOVER)
    target = np.where(holding[:, None], goal, target)  # carry it to the goal
    gripper = np.where(holding | at_cube, -1.0, 1.0)  # close on the cube, else open
    return np.concatenate([_clipped_action(target, ee), gripper[:, None]], axis=1)


_EXPERTS = {"reach": _reach, "push": _push, "pick_and_place": _pick_and_place}


class ScriptedExpert(Policy):
    """State-machine expert with optional Gaussian action noise of std `noise_std`."""

    name = "scripted"

    def __init__(self, task: str, noise_std: float = 0.0) -> None:
        super().__init__(task)
        if self.task not in _EXPERTS:
            raise GcdtError(
                f"no scripted expert for task {self.task!r}: scripted experts cover "
                f"{', '.join(_EXPERTS)}"
            )
        if not noise_std >= 0.0:
            raise GcdtError(f"noise_std must be >= 0, got {noise_std!r}")
        self.noise_std = float(noise_std)
        self._act = _EXPERTS[self.task]

    def predict(
        self, obs: Mapping[str, np.ndarray], episode_start: np.ndarray, reward: np.ndarray
    ) -> np.ndarray:
        action = np.clip(self._act(obs), -1.0, 1.0).astype(np.float32)
        if self.noise_std == 0:
            return action
        self.intended = action
        noisy = action + self.rng.normal(0.0, self.noise_std, size=action.shape)
        return np.clip(noisy, -1.0, 1.0).astype(np.float32)

    def config(self) -> dict[str, Any]:
        return {**super().config(), "noise_std": self.noise_std}
