"""The benchmarkable-agent protocol: all the harness needs of an agent, and the registry of agents.

`evaluation/run.py` trains, evaluates, saves and reloads agents only through this protocol, so an agent
of your own — built on anything — is benchmarked exactly like the built-in presets once registered:

    from hyperstate import evaluation

    @evaluation.register_agent("my_agent")
    def make_my_agent(**overrides):        # overrides: the --config table of "my_agent" (and "all")
        return MyAgent(**overrides)

    python evaluation/run.py --import my_agents.py --agents my_agent oracle --tasks cheetah_dir_sparse ...

An agent has:
- `train(task, frames, seed, *, checkpoint_dir, resume, on_iteration)`: train on the registered task
  `task` for `frames` environment steps; write checkpoints under `checkpoint_dir` and continue from them
  when `resume`; call `on_iteration(log)` regularly with `log["frames"]` (steps so far) — when it returns
  True (the harness evaluated), checkpoint now if you can, so that a resumed run rejoins the curve.
  It may also accept `progress` (bool) and `on_rollout(observations)` ((T, N, ...) arrays per key, for
  the hyper-state coverage metric); the harness passes them only where the signature has them.
- `act(obs, state=None, deterministic=True, reward=None) -> (action, state)`: a batch of observations
  (dicts of (M, ...) arrays from `suite.batch(..., privileged=True)`: ignore the privileged `belief` and
  `task` keys unless you are a reference), `state=None` at the start of a BAMDP episode, afterwards the
  returned state with the previous step's `reward`.
- `save(path)` and a loader: a classmethod `load(path)` on the agent's class, or `register_agent(...,
  loader=...)`.
- optionally `belief_features(state) -> (M, F) array` (for the belief probe), `reads_true_task` (True
  for a task-aware reference), `check_task(task, task_kwargs)` (raise ValueError if it cannot run there),
  `config` (a dataclass or dict, recorded with the results) and `total_frames` (the steps it trained).
"""

from __future__ import annotations

import dataclasses
import inspect
import os
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from hyperstate import agents
from hyperstate.registry import Registry, unknown_name


class BenchmarkAgent(Protocol):
    """What `evaluation/run.py` needs of an agent (see the module docstring)."""

    def train(self, task: str, frames: int, seed: int, *, checkpoint_dir, resume: bool, on_iteration) -> Any: ...

    def act(
        self, obs: dict[str, np.ndarray], state: Any = None, deterministic: bool = True, reward: Any = None
    ) -> tuple[np.ndarray, Any]: ...

    def save(self, path: str | os.PathLike) -> None: ...


@dataclasses.dataclass(frozen=True)
class AgentEntry:
    name: str
    factory: Callable[..., Any]
    loader: Callable[[str | os.PathLike], Any] | None


_AGENTS: Registry[AgentEntry] = Registry("agent", "agents")


def register_agent(
    name: str, *, loader: Callable[[str | os.PathLike], Any] | None = None
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Decorator registering `factory(**overrides) -> agent` as the agent `name` for `evaluation/run.py`.

    `loader(path) -> agent` reloads what the agent's `save` wrote; by default the `load` classmethod of
    the class the factory returns. Names of built-in presets (`agents.PRESETS`) are taken.
    """
    _AGENTS.check_free(name)

    def decorator(factory: Callable[..., Any]) -> Callable[..., Any]:
        _AGENTS.check_free(name)
        if name in agents.PRESETS:
            raise ValueError(f"agent {name!r} is already registered (as a preset of hyperstate.agents)")
        _AGENTS.add(name, AgentEntry(name, factory, loader), owner=getattr(factory, "__module__", "?"))
        return factory

    return decorator


def unregister_agent(name: str) -> None:
    """Removes an agent registered with `register_agent` (mainly for tests and notebooks)."""
    _AGENTS.remove(name)


def agent_names() -> list[str]:
    """Every name `--agents` accepts: built-in presets (and `agents.register_preset` ones) and registered agents."""
    return sorted({*agents.PRESETS, *_AGENTS})


def check_name(name: str) -> None:
    """ValueError with a did-you-mean if nobody registered `name`."""
    if name not in _AGENTS and name not in agents.PRESETS:
        raise unknown_name("agent", name, agent_names(), "agents")


def make_agent(name: str, **overrides: Any) -> BenchmarkAgent:
    """A fresh agent `name` with config overrides: a registered factory, or a preset via `agents.make`."""
    check_name(name)
    if name in _AGENTS:
        return _AGENTS[name].factory(**overrides)
    return agents.make(name, **overrides)


def load_agent(name: str, path: str | os.PathLike) -> BenchmarkAgent:
    """Reloads what agent `name`'s `save(path)` wrote."""
    check_name(name)
    entry = _AGENTS.get(name)
    if entry is None:
        return agents.Agent.load(path)
    if entry.loader is not None:
        return entry.loader(path)
    load = getattr(type(entry.factory()), "load", None)
    if load is None:
        raise TypeError(
            f"agent {name!r} has no loader: give its class a load(path) classmethod, or register_agent(loader=)"
        )
    return load(path)


def describe(agent: Any) -> dict:
    """The agent's config as JSON-ready data (a dataclass or a dict), or {}."""
    config = getattr(agent, "config", None)
    if dataclasses.is_dataclass(config) and not isinstance(config, type):
        return dataclasses.asdict(config)
    return dict(config) if isinstance(config, dict) else {}


def reads_true_task(agent: Any) -> bool:
    """Whether the agent is conditioned on the true task (a reference, not a meta-learner)."""
    return bool(getattr(agent, "reads_true_task", False))


def check_task(agent: Any, task: str, task_kwargs: dict | None = None) -> None:
    """The agent's own check that it can run on `task`, where it has one."""
    check = getattr(agent, "check_task", None)
    if check is not None:
        check(task, task_kwargs)


def train(agent: Any, task: str, frames: int, seed: int, **options: Any) -> Any:
    """Calls `agent.train` with the protocol's arguments plus those optional ones its signature accepts."""
    required = ("checkpoint_dir", "resume", "on_iteration")
    parameters = inspect.signature(agent.train).parameters
    takes_any = any(p.kind is p.VAR_KEYWORD for p in parameters.values())
    kwargs = {k: v for k, v in options.items() if k in required or takes_any or k in parameters}
    return agent.train(task, frames, seed, **kwargs)
