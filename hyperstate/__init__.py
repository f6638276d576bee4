"""hyperstate: a sparse-reward meta-RL benchmark suite (exploration in approximate hyper-state space).

    from hyperstate import suite        # tasks, priors, exact beliefs, BAMDP horizons, the task registry
    from hyperstate import agents       # PPO from belief and bonus components, presets
    from hyperstate import evaluation   # the grid harness (evaluation/run.py)

In the repository the three packages are the folders `suite/`, `agents/` and `evaluation/`; the
install maps them under this name (setup.cfg `package_dir`), so nothing collides with dm_control's
`suite` or with unrelated packages called `agents` or `evaluation`.
"""

from importlib import metadata as _metadata

try:
    __version__ = _metadata.version("hyperstate")
except _metadata.PackageNotFoundError:  # imported from a checkout that is not installed
    __version__ = "unknown"
