"""Belief components: what the policy knows about the task beyond the current state.

Every belief follows one protocol. Its state `b_t` summarises everything observed up to s_t; it starts
from a prior at the start of each BAMDP episode and is updated with each transition (a_t, r_t, s_{t+1}).
`features(b_t)` is what the policy and the hyper-state bonus see.

- `none`: no features (a Markov policy on the state).
- `oracle`: the exact belief the task hands over as privileged information (the paper's Belief Oracle).
- `recurrent`: RL²; a GRU trained by the RL loss through time.
- `varibad`: variBAD's VAE; the policy sees the posterior (mean, logvar), detached.
- `task_supervised`: the same encoder trained to predict the true task parameters (Humplik et al. 2019).
- `task_aware`: the true task parameters (privileged): the reference policy that knows the task.

One module per component, each registered where it is defined (`@register_belief(name)`).
"""

from hyperstate.agents.beliefs.base import (
    Belief,
    Stateless,
    Trajectories,
    Transition,
    belief_class,
    list_beliefs,
    make_belief,
    no_params,
    register_belief,
    unregister_belief,
    where,
)
from hyperstate.agents.beliefs.none import NoBelief
from hyperstate.agents.beliefs.oracle import OracleBelief, TaskAwareBelief
from hyperstate.agents.beliefs.recurrent import RecurrentBelief
from hyperstate.agents.beliefs.task_supervised import TaskSupervisedBelief
from hyperstate.agents.beliefs.varibad import VariationalEncoder, VariBADBelief, gaussian_kl, kl_to_previous

__all__ = [
    "Belief",
    "NoBelief",
    "OracleBelief",
    "RecurrentBelief",
    "Stateless",
    "TaskAwareBelief",
    "TaskSupervisedBelief",
    "Trajectories",
    "Transition",
    "VariBADBelief",
    "VariationalEncoder",
    "belief_class",
    "gaussian_kl",
    "kl_to_previous",
    "list_beliefs",
    "make_belief",
    "no_params",
    "register_belief",
    "unregister_belief",
    "where",
]
