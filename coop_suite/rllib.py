"""An RLlib `MultiAgentEnv` for every coop_suite task (optional extra).

    pip install -e .[rllib]

    from ray.rllib.algorithms.ppo import PPOConfig
    from coop_suite import rllib
    config = PPOConfig().environment(
        rllib.MultiAgentEnv, env_config={"task": "corridor", "n_agents": 4})

    env = coop_suite.rllib_env("ravine", 2)   # or directly
    observations, infos = env.reset(seed=0)

A thin layer over the PettingZoo adapter (`coop_suite.pettingzoo.ParallelEnv`),
so agent ids, spaces, seeding and the split between termination (the task
ended the episode: no bootstrapping) and truncation (the time limit) are the
same as there (docs/pettingzoo.md); this adds RLlib's `"__all__"` entries,
which follow the agents' (all agents end together). Observations are one
flat float32 vector per agent by default (`flatten=False` for a `Dict`),
the layout RLlib's default encoders take.
"""

import coop_suite.pettingzoo

try:
  from ray.rllib.env import multi_agent_env
except ImportError as e:  # pragma: no cover - depends on the install.
  raise ImportError(
      "coop_suite.rllib needs the optional RLlib extra: "
      "pip install -e .[rllib]") from e

__all__ = ["MultiAgentEnv"]


class MultiAgentEnv(multi_agent_env.MultiAgentEnv):
  """RLlib view of a coop_suite task; see the module docstring."""

  def __init__(self, config=None):
    """Args:
      config: RLlib's `env_config` dict: `task` (default 'transport'),
        `n_agents`, `flatten` (default True), `render_mode`, `render_size`,
        and any `coop_suite.load` option (`seed`, `time_limit`, task
        options such as `stage`).
    """
    super().__init__()
    # RLlib passes an EnvContext (a dict with worker ids): keep the options.
    self._config = dict(config or {})
    options = dict(self._config)
    task = options.pop("task", "transport")
    n_agents = options.pop("n_agents", None)
    adapter_options = {k: options.pop(k) for k in
                       ("flatten", "render_mode", "render_size")
                       if k in options}
    adapter_options.setdefault("flatten", True)
    self.parallel_env = coop_suite.pettingzoo.ParallelEnv(
        coop_suite.load(task, n_agents, **options), **adapter_options)
    self.possible_agents = list(self.parallel_env.possible_agents)
    self.agents = []
    self.observation_spaces = dict(self.parallel_env.observation_spaces)
    self.action_spaces = dict(self.parallel_env.action_spaces)
    self.render_mode = self.parallel_env.render_mode
    self.metadata = self.parallel_env.metadata

  def reset(self, *, seed=None, options=None):
    """(observations, infos) keyed by agent id; `seed` reseeds the
    environment (the same seed gives the same episode)."""
    observations, infos = self.parallel_env.reset(seed=seed, options=options)
    self.agents = list(self.parallel_env.agents)
    return observations, infos

  def step(self, action_dict):
    """(observations, rewards, terminateds, truncateds, infos), each keyed
    by agent id; `terminateds` and `truncateds` also hold `"__all__"`."""
    observations, rewards, terminateds, truncateds, infos = (
        self.parallel_env.step(action_dict))
    self.agents = list(self.parallel_env.agents)
    terminateds["__all__"] = all(terminateds.values())
    truncateds["__all__"] = all(truncateds.values())
    return observations, rewards, terminateds, truncateds, infos

  def render(self):
    return self.parallel_env.render()

  def close(self):
    self.parallel_env.close()

  def __reduce__(self):
    """Pickles as its config: RLlib ships environments to its workers."""
    return MultiAgentEnv, (self._config,)
