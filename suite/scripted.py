"""Scripted strategies: baselines that need no learning, and bounds on what a task's best agent earns.

- Cheetah: open-loop sinusoid gaits, found by random search over their parameters; they carry the
  cheetah about 15-19 m in one 200-step episode from most initial poses, backward more reliably than
  forward. Used by the demo and the tests.
- Mountain Treasure: `MountainClimber` (climb, read the map, walk straight to the treasure: the
  Bayes-optimal strategy's shape) and `CircleWalker` (walk the circle until the treasure pays: what a
  meta-learner that does not explore does).
- Rooms: `RoomsExplorer` visits the candidate corners of each stage in a fixed order until the stage
  pays, then the next stage's, then stays on goal 3.
- Point robot: `PointExplorer` visits the candidate goals from one end of the half circle to the other
  until one pays and returns to it in every later MDP episode (the Bayes-optimal strategy's shape on a
  finite prior); `ArcSweeper` does the same along the whole half circle (a continuous prior);
  `PointGoalSeeker` reads the true goal (privileged observations) and goes straight to it: the
  task-aware bound.

A strategy is called with each step's observation and reward (`act(observation, reward)`) and
`reset()` at every BAMDP episode start; `rollout(env, strategy)` runs one BAMDP episode.
"""

from __future__ import annotations

import numpy as np

from hyperstate.suite import mountain_treasure, point_robot, rooms
from hyperstate.suite.cheetah_dir import BACKWARD, CONTROL_TIMESTEP, FORWARD


class SinusoidGait:
    """Action a_j(t) = amplitude_j * sin(2 pi frequency t + phase_j), t the time since episode start."""

    def __init__(self, frequency: float, amplitude, phase):
        self.frequency = float(frequency)
        self.amplitude = np.asarray(amplitude, dtype=np.float64)
        self.phase = np.asarray(phase, dtype=np.float64)

    def __call__(self, step: int) -> np.ndarray:
        return self.amplitude * np.sin(2 * np.pi * self.frequency * step * CONTROL_TIMESTEP + self.phase)


GAITS = {
    FORWARD: SinusoidGait(3.77, [0.908, 0.521, 0.656, 0.716, 0.806, 0.403], [0.595, 2.154, 1.173, 4.68, 4.012, 3.174]),
    BACKWARD: SinusoidGait(
        3.324, [0.959, 0.546, 0.602, 0.509, 0.983, 0.555], [1.401, 2.754, 3.481, 4.665, 1.257, 5.452]
    ),
}


def gait(direction: float) -> SinusoidGait:
    """The scripted gait running in `direction` (+1 forward, -1 backward)."""
    return GAITS[float(direction)]


def rollout(env, strategy) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """One BAMDP episode of `strategy` on dm_control environment `env`: its rewards (T,) and the
    observations each step ended in, stacked ({key: (T, ...)})."""
    strategy.reset()
    step = env.reset()
    rewards, observations = [], []
    reward = 0.0
    while not step.last():
        step = env.step(strategy.act(step.observation, reward))
        reward = float(step.reward)
        rewards.append(reward)
        observations.append(step.observation)
    return np.array(rewards), {k: np.stack([o[k] for o in observations]) for k in observations[0]}


def _toward(position: np.ndarray, target: np.ndarray, step_size: float) -> np.ndarray:
    """The action of a single-integrator walker heading straight for `target` (arriving, not overshooting)."""
    move = (np.asarray(target) - position) / step_size
    return move / max(1.0, float(np.abs(move).max()))


class MountainClimber:
    """Mountain Treasure: up to the top, read the map, straight to the treasure, stay there."""

    def reset(self) -> None:
        self.treasure = None

    def act(self, observation: dict, reward: float) -> np.ndarray:
        if np.any(observation["treasure_map"] != 0):
            self.treasure = observation["treasure_map"].copy()
        target = np.zeros(2) if self.treasure is None else self.treasure
        return _toward(observation["position"], target, mountain_treasure.STEP_SIZE)


class CircleWalker:
    """Mountain Treasure: along the treasure circle (counter-clockwise) until the treasure pays, then stay."""

    def reset(self) -> None:
        self.found = None

    def act(self, observation: dict, reward: float) -> np.ndarray:
        position = observation["position"]
        if reward > 0 and self.found is None:
            self.found = position.copy()
        if self.found is not None:
            return _toward(position, self.found, mountain_treasure.STEP_SIZE)
        radius = max(float(np.linalg.norm(position)), 1e-9)
        angle = np.arctan2(position[1], position[0]) + 0.1 / mountain_treasure.TREASURE_DISTANCE
        ahead = mountain_treasure.TREASURE_DISTANCE * np.array([np.cos(angle), np.sin(angle)])
        return _toward(position, ahead if radius > 0.5 else position / radius, mountain_treasure.STEP_SIZE)


class RoomsExplorer:
    """Rooms: tries the candidate corners of goal 1, then of goal 2 (in the room on goal 1's side), then
    of goal 3 (the middle room's others), each stage until it pays; stays on goal 3. Moves through
    waypoints with a damped proportional controller; the corridor is entered and left at its ends."""

    GAIN, DAMPING, TOLERANCE = 8.0, 0.8, 0.06

    def reset(self) -> None:
        self.stage = 0
        self.goals: list[np.ndarray] = []
        self.tried: set[tuple[int, int]] = set()
        self.route: list[np.ndarray] = []

    def _route_to(self, position: np.ndarray, target: np.ndarray) -> list[np.ndarray]:
        here, there = rooms.cell_of(position), rooms.cell_of(target)
        room = lambda cell: int(np.sign(cell[0])) if abs(cell[0]) > rooms.HALF else 0  # noqa: E731
        if room(here) == room(there):
            return [target]
        side = room(there) or room(here)
        near, far = (
            rooms.CELL * np.array([side * rooms.HALF, 0]),
            rooms.CELL * np.array([side * (rooms.SIDE_CENTRE - rooms.HALF), 0]),
        )
        door = [near, far] if room(there) else [far, near]
        return [*door, target]

    def _next_target(self, position: np.ndarray) -> np.ndarray | None:
        if self.stage == 3:
            return self.goals[2]
        if self.stage == 0:
            corners = rooms.MIDDLE_CORNERS
        elif self.stage == 1:
            corners = rooms.LEFT_CORNERS if self.goals[0][0] < 0 else rooms.RIGHT_CORNERS
        else:
            goal_1 = tuple(rooms.cell_of(self.goals[0]))
            corners = [c for c in rooms.MIDDLE_CORNERS if c != goal_1]
        left = [c for c in corners if c not in self.tried]
        if not left:
            return None
        here = rooms.cell_of(position)
        closest = min(left, key=lambda c: abs(c[0] - here[0]) + abs(c[1] - here[1]))
        return rooms.CELL * np.array(closest, dtype=np.float64)

    def act(self, observation: dict, reward: float) -> np.ndarray:
        position, velocity = observation["position"], observation["velocity"]
        cell = tuple(int(v) for v in rooms.cell_of(position))
        if reward in rooms.GOAL_REWARDS[self.stage : self.stage + 1]:
            self.goals.append(position.copy())
            self.stage += 1
            self.tried, self.route = set(), []
        elif self.stage < 3 and cell in (*rooms.MIDDLE_CORNERS, *rooms.LEFT_CORNERS, *rooms.RIGHT_CORNERS):
            if self.route and np.array_equal(rooms.cell_of(self.route[-1]), cell):
                self.tried.add(cell)
                self.route = []
        if self.route and np.linalg.norm(self.route[0] - position) < self.TOLERANCE and len(self.route) > 1:
            self.route.pop(0)
        if not self.route:
            target = self._next_target(position)
            if target is None:
                return np.zeros(2)
            self.route = self._route_to(position, target)
        return np.clip(self.GAIN * (self.route[0] - position) - self.DAMPING * velocity, -1.0, 1.0)


def _damped(observation: dict, target: np.ndarray, gain: float = 8.0, damping: float = 0.8) -> np.ndarray:
    """The point mass's action toward `target`: a proportional controller with velocity damping (the
    closed loop is about critically damped for the 0.2 s velocity lag of the point robot and Rooms)."""
    return np.clip(gain * (target - observation["position"]) - damping * observation["velocity"], -1.0, 1.0)


class PointExplorer:
    """Point robot, finite prior: visits the candidate goals in order (angle 0 to π), each until the
    robot is within `reach` of it, until a step pays; from then on it goes to the paying candidate, in
    this and every later MDP episode. `candidates` (K, 2), e.g.
    `point_robot.HalfCircleGoalPrior(num_goals=K).support()`."""

    snap_to_candidate = True  # a paying step reveals the goal: the candidate nearest to it

    def __init__(self, candidates: np.ndarray, reach: float = 0.1):
        self.candidates = np.asarray(candidates, dtype=np.float64)
        self.reach = float(reach)

    def reset(self) -> None:
        self.found: np.ndarray | None = None
        self.next = 0
        self.episode = 0.0

    def act(self, observation: dict, reward: float) -> np.ndarray:
        position, episode = observation["position"], float(observation["inner_episode"][0])
        if reward > 0 and self.found is None:
            # A step that ends an MDP episode shows the next one's start, not where it paid: then the
            # step paid on the way to the candidate it was heading for.
            paid_at = self.candidates[self.next] if episode != self.episode else position
            nearest = self.candidates[np.argmin(np.linalg.norm(self.candidates - paid_at, axis=1))]
            self.found = (nearest if self.snap_to_candidate else paid_at).copy()
        self.episode = episode
        if self.found is not None:
            return _damped(observation, self.found)
        while (
            self.next < len(self.candidates) - 1 and np.linalg.norm(position - self.candidates[self.next]) < self.reach
        ):
            self.next += 1
        return _damped(observation, self.candidates[self.next])


class ArcSweeper(PointExplorer):
    """Point robot, continuous prior: out to the half circle's end at angle 0, then along it to angle π
    (waypoints `spacing` radians apart) until a step pays; from then on it goes to where the step paid."""

    snap_to_candidate = False

    def __init__(self, spacing: float = 0.1, reach: float = 0.1):
        angles = np.arange(0.0, np.pi + 1e-9, spacing)
        super().__init__(point_robot.GOAL_DISTANCE * np.stack([np.cos(angles), np.sin(angles)], 1), reach)


class PointGoalSeeker:
    """Point robot: straight to the true goal in every MDP episode (needs `privileged=True`: it reads the
    `task` observation), and stays there. Not a meta-learner: the task-aware bound of the bracket."""

    def reset(self) -> None:
        pass

    def act(self, observation: dict, reward: float) -> np.ndarray:
        return _damped(observation, np.asarray(observation["task"], dtype=np.float64))
