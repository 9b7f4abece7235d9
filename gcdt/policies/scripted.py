"""Scripted state-machine experts for Reach, Push and PickAndPlace.

They replace the paper's TQC experts where a trained TQC agent is too costly (2-core CPU
profiles). Each expert reads its phase from the current observation alone (no hidden
state), so it recovers by itself when the object slips, and it is vectorised over envs.

panda-gym's end-effector control moves the gripper towards `ee + 0.05 * action[:3]` each step,
so every phase below picks a target point and the action is the clipped displacement to it.
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

# Push: the closed fingertips come down this far behind the cube's centre, clear of its
# corners even when it has turned (half diagonal 2.8 cm), then push towards the goal.
PUSH_CONTACT = 0.055
PUSH_Z = 0.02  # fingertip height while pushing (cube centre height)
PUSH_SPEED = 0.4  # action limit while in contact with the cube (2 cm per step)
PUSH_DEPTH = 0.04  # how far ahead of the gripper, along the cube-goal line, a push aims
SAFE_Z = 0.1  # height at which the fingers clear the cube when repositioning

# PickAndPlace: finger width (sum of both fingers) when closed on the 4 cm cube, and open.
GRASP_WIDTH = 0.045
MISSED_WIDTH = 0.03


def _to_action(target: np.ndarray, ee: np.ndarray, limit: np.ndarray | float = 1.0) -> np.ndarray:
    """Displacement towards `target`, its norm at most `limit` (per env).

    Scaling the whole vector (not clipping each coordinate) keeps the direction of motion,
    which matters when pushing: a clipped diagonal push turns into an axis-aligned one.
    """
    action = (target - ee) / ACTION_SCALE
    norm = np.linalg.norm(action, axis=-1, keepdims=True)
    scale = np.minimum(1.0, np.reshape(limit, (-1, 1)) / np.maximum(norm, 1e-9))
    return np.clip(action * scale, -1.0, 1.0)


def _reach(obs: Mapping[str, np.ndarray]) -> np.ndarray:
    ee = obs["observation"][:, 0:3]
    return _to_action(obs["desired_goal"], ee)


def _push(obs: Mapping[str, np.ndarray]) -> np.ndarray:
    o = obs["observation"]
    ee, obj, goal = o[:, 0:3], o[:, 6:9], obs["desired_goal"]

    to_goal = goal[:, :2] - obj[:, :2]
    dist = np.linalg.norm(to_goal, axis=1, keepdims=True)
    direction = to_goal / np.maximum(dist, 1e-6)  # unit push direction, [n, 2]
    behind = obj[:, :2] - direction * PUSH_CONTACT  # where the fingertips must be to push

    rel = ee[:, :2] - obj[:, :2]
    along = np.sum(rel * direction, axis=1)  # < 0 when the gripper is behind the cube
    lateral = np.linalg.norm(rel - along[:, None] * direction, axis=1)
    low = ee[:, 2] < PUSH_Z + 0.02
    # Loose once low and pushing: the cube turns and drifts a little, and the push target
    # below steers back onto the line; only a lost cube is worth a new approach.
    in_line = (along < -CUBE_HALF) & (lateral < np.where(low, 0.03, 0.01))
    # Wider once on the way down, so a slightly moving approach point does not abort it.
    on_the_way_down = ee[:, 2] < SAFE_Z - 0.01
    over_behind = np.linalg.norm(ee[:, :2] - behind, axis=1) < np.where(on_the_way_down, 0.02, 0.01)

    pushing = in_line & low
    descending = ~pushing & over_behind
    lifting = ~pushing & ~descending & low  # low but misaligned: lift before moving over
    # Push: move forward along the cube-goal line (steering back onto it), slower near the goal.
    depth = np.minimum(dist, PUSH_DEPTH)
    target = np.empty_like(ee)
    push_to = obj[:, :2] + (along[:, None] + depth) * direction  # forward on the line
    target[:, :2] = np.where(pushing[:, None], push_to, behind)
    target[:, :2] = np.where(lifting[:, None], ee[:, :2], target[:, :2])
    # Reposition no lower than SAFE_Z and never downwards: a diagonal descent overshoots
    # (the arm lags its target) and knocks the cube before the gripper is behind it.
    target[:, 2] = np.where(pushing | descending, PUSH_Z, np.maximum(ee[:, 2], SAFE_Z))
    # A full-speed push launches the cube, which then slides past the goal or off the table.
    # Slowing down over the last 10 cm keeps the cube from sliding past the goal.
    push_speed = np.clip(dist[:, 0] / 0.1, 0.5, 1.0) * PUSH_SPEED
    return _to_action(target, ee, np.where(pushing, push_speed, 1.0))


def _pick_and_place(obs: Mapping[str, np.ndarray]) -> np.ndarray:
    o = obs["observation"]
    ee, width, obj, goal = o[:, 0:3], o[:, 6], o[:, 7:10], obs["desired_goal"]

    rel = obj - ee
    horizontal = np.linalg.norm(rel[:, :2], axis=1)
    at_cube = (horizontal < 0.01) & (np.abs(rel[:, 2]) < 0.01)
    holding = (horizontal < 0.02) & (np.abs(rel[:, 2]) < 0.02) & (width < GRASP_WIDTH)
    holding &= width > MISSED_WIDTH  # closed on nothing: the grasp missed
    above = horizontal < 0.01

    target = obj + np.array([0.0, 0.0, 0.03])  # approach from above, fingers open
    target = np.where(above[:, None], obj, target)  # then descend onto the cube
    target = np.where(holding[:, None], goal, target)  # carry it to the goal
    gripper = np.where(holding | at_cube, -1.0, 1.0)  # close on the cube, else open
    # Closing takes a few steps: hold still meanwhile so the fingers close around the cube.
    target = np.where((at_cube & ~holding)[:, None], ee, target)
    return np.concatenate([_to_action(target, ee), gripper[:, None]], axis=1)


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
