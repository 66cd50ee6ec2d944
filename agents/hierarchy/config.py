"""Hyper-parameters of the hierarchical agent, one frozen dataclass.

Defaults are the paper's where it gives them (section 5: IPPO, Adam lr 5e-4
to start from, PPO clip 0.2); the stability settings (value normalisation, a
critic of its own, KL-adaptive learning rate, std floor, discount per
command) are explained in docs/training.md, "Stability"; the others follow
PureJaxRL's `ppo_rnn` and the project's PPO (`agents.ppo.config`). One
config describes one species; the runner makes a learner and actor per
species. The variant 'lowlevel' is the lower layer itself, trained on a
locomotion task (`coop-pretrain-lowlevel` sets its Brax-like settings).
"""
import dataclasses

from agents import fields
from agents import observations as obs_lib

AGENTS = ('hrl', 'no_memory', 'flat', 'mappo', 'lowlevel')
CRITICS = ('separate', 'stop_gradient', 'shared')


@dataclasses.dataclass(frozen=True)
class HierarchyConfig:
  """Everything that decides the agent's networks and how they learn."""

  agent: str = fields.field('hrl', fields.one_of(*AGENTS))
  """Variant (paper section 6 ablations): 'hrl' = UL MLP + ML GRU (default);
  'no_memory' = an MLP in place of the GRU (Nachum et al. 2019); 'flat' = one
  MLP from proprio + extero to the joint actions, no lower layer; 'mappo' =
  'hrl' whose critic also reads the global state (centralised critic);
  'lowlevel' = the lower layer: the 'flat' networks from proprio + command
  to the joint actions, on a locomotion task (walk_to_target,
  walk_velocity) with its own rewards, exported as a controller
  (`agents.lowlevel`)."""
  critic: str = fields.field('separate', fields.one_of(*CRITICS))
  """How the critic relates to the policy's upper and middle layers, the same
  for 'hrl', 'no_memory' and 'mappo' ('flat' always has its own value MLP):
  'separate' = an upper and middle layer of its own (the value loss cannot
  move the policy's parameters); 'stop_gradient' = the value head reads the
  policy's middle-layer features through a stop-gradient; 'shared' = the
  value head trains the policy's trunk too (the layout of the first
  transport run, which collapsed; kept to reproduce it)."""

  # Optimisation.
  learning_rate: float = fields.field(5e-4, fields.POSITIVE)
  """Adam step size at the start (paper); then adapted, see `target_kl`."""
  target_kl: float = fields.field(0.008, fields.NON_NEGATIVE)
  """KL-adaptive learning rate (the paper's rl_games, `agents.ppo.step_size`):
  after each minibatch the rate is divided by 1.5 if its approximate KL to
  the behaviour policy is above 2 x target_kl and multiplied by 1.5 below
  target_kl / 2. 0 keeps `learning_rate` constant."""
  adam_epsilon: float = fields.field(1e-5, fields.POSITIVE)
  """Adam's denominator epsilon (CleanRL / PureJaxRL)."""
  max_grad_norm: float = fields.field(1.0, fields.POSITIVE)
  """Gradients are rescaled to at most this global L2 norm. With normalised
  advantages and values both losses are O(1) and so are their gradients; 1.0
  (rl_games' Ant setting) clips outliers, not every step."""
  num_epochs: int = fields.field(4, fields.COUNT)
  """Passes over each batch of sequences."""
  num_minibatches: int = fields.field(4, fields.COUNT)
  """Minibatches per epoch, split along the batch axis B (sequences stay
  whole), which must divide by it."""

  # PPO objective.
  discount: float = fields.field(0.99, fields.UNIT)
  """Per-command discount gamma; multiplied by the 0/1 env discount. The
  paper's 0.995 is per simulator step; per 0.5 s command it would be a
  horizon 1 / (1 - gamma) of 200 commands = 100 s, beyond a 40 s episode.
  0.99 is 100 commands = 50 s: a success at an episode's end is still worth
  0.99^80 = 0.45 of itself at its start, and returns stay ~2x shorter."""
  gae_lambda: float = fields.field(0.95, fields.UNIT)
  """GAE lambda: 0 is one-step TD, 1 is Monte-Carlo returns."""
  clip_epsilon: float = fields.field(0.2, fields.POSITIVE)
  """PPO trust region: ratios clipped to [1 - eps, 1 + eps] (paper)."""
  clip_value_loss: bool = False
  """Also clip value updates to +-clip_epsilon (CleanRL's option)."""
  entropy_cost: float = fields.field(1e-2, fields.NON_NEGATIVE)
  """Weight of the entropy bonus (Brax's and the lower layer's). 1e-3 was
  30-60x weaker than the policy loss and the std fell 0.69 -> 0.03 in the
  first transport run; with 1e-2 and `min_action_std` exploration stays."""
  min_action_std: float = fields.field(0.1, fields.NON_NEGATIVE)
  """Floor of the command's std in pre-tanh units (softplus(s) + floor):
  the policy's sensitivity to a parameter step grows as 1 / std, so a
  collapsing std made every update larger. Evaluation acts with the mean."""
  initial_action_std: float = fields.field(
      0.0, fields.equal(0, 'softplus(0) + min_action_std') | fields.POSITIVE)
  """The command's std at initialisation, pre-tanh (> min_action_std);
  0 keeps the default softplus(0) + min_action_std ~= 0.79 (~1.7 m a
  command at the ravine). The ravine's crossers stage starts smaller
  (`runners.paper_plan.CROSSERS_FLAGS`): around a fresh policy's ~zero
  mean, the default noise walked crossers off the stone's ends.
  State-independent std only (`state_dependent_std` False); the learned
  std then moves as usual."""
  value_cost: float = fields.field(0.5, fields.NON_NEGATIVE)
  """Weight of the value loss 0.5 * (target - value)^2, in normalised units
  when `normalize_values`."""
  normalize_values: bool = True
  """The critic predicts returns standardised by running statistics of all
  value targets (MAPPO's ValueNorm, `agents.ppo.returns`), saved with the
  learner state."""
  normalize_advantages: bool = True
  """Standardise advantages within each minibatch."""
  reward_scaling: float = fields.field(0.01, fields.POSITIVE)
  """Rewards are multiplied by this before GAE. The paper's rewards summed
  over a 0.5 s command reach ~40 per command and ~3000 per episode; unscaled,
  the value loss (~3e4) dominates the clipped global gradient norm and the
  policy barely moves (measured: approx_kl ~1e-4 per update)."""

  # Data.
  sequence_length: int = fields.field(32, fields.COUNT)
  """T, commands per training sequence (truncated BPTT length): the actor
  hands over a `SequenceBatch` every T commands, its GRU state stored at the
  start of the sequence. 32 commands = 16 s at a 0.5 s command period; with
  2 actors x 16 copies x 4 agents an update sees 4,096 commands."""
  normalize_observations: bool = True
  """Standardise observations and the global state with running statistics
  (`agents.normalization`), updated by the learner before each update."""
  observation_clip: float = fields.field(5.0, fields.POSITIVE)
  """Normalised inputs are clipped to [-clip, clip]."""
  seed: int = fields.field(0, fields.SEED)
  """Seed of parameter initialisation, minibatch shuffling and action noise
  (the builder folds in the species and actor ids); `coop-train` seeds the
  environments with it too."""

  # Networks.
  upper_layer_sizes: tuple[int, ...] = fields.field((128, 128), fields.COUNT)
  """UL: hidden widths of the MLP over the exteroceptive features."""
  middle_layer_size: int = fields.field(128, fields.COUNT)
  """ML: GRU hidden size h ('hrl', 'mappo'), or the width of the MLP layer
  replacing it ('no_memory'). Also the carry width of every variant, so that
  actor and learner handle one carry shape."""
  head_sizes: tuple[int, ...] = fields.field((128,), fields.COUNT)
  """Hidden widths of the command head and the value head on top of the ML
  (the critic's own ML with `critic='separate'`)."""
  critic_sizes: tuple[int, ...] = fields.field((128, 128), fields.COUNT)
  """'mappo': widths of the MLP over the global state whose features join
  the critic's middle-layer features before the value head."""
  flat_sizes: tuple[int, ...] = fields.field((256, 256), fields.COUNT)
  """'flat', 'lowlevel': hidden widths of the policy MLP and its separate
  value MLP (the lower layer's own architecture)."""
  activation: str = 'swish'
  """Hidden activation of all MLPs, by name (see `agents.networks.mlp`)."""
  state_dependent_std: bool = False
  """False: the action std is a learned parameter vector, the same for every
  state (PureJaxRL); exploration then cannot collapse in some states while
  the value is still poor. True: the head outputs it (Brax). Both start at
  softplus(0) + min_action_std ~= 0.79 in pre-tanh units (False: unless
  `initial_action_std` says otherwise). Always True for 'lowlevel':
  a controller's policy outputs its std (`agents.networks.policy_value`)."""

  @property
  def recurrent(self) -> bool:
    """Whether the middle layer carries a hidden state between commands."""
    return self.agent in ('hrl', 'mappo')

  @property
  def uses_commands(self) -> bool:
    """Whether the policy commands the frozen lower layer (every variant but
    'flat' and 'lowlevel', which emit joint actions every control step)."""
    return self.agent not in ('flat', 'lowlevel')

  @property
  def adds_locomotion_terms(self) -> bool:
    """Whether the task's reward gets the lower layer's locomotion terms
    added ('flat'; a locomotion task, which 'lowlevel' trains on, has
    them already)."""
    return self.agent == 'flat'

  @property
  def uses_global_state(self) -> bool:
    """Whether the critic reads a `global_state` input ('mappo')."""
    return self.agent == 'mappo'

  @property
  def observation_prefixes(self) -> tuple[str, ...]:
    """Observation groups the networks read, in flattening order (see
    `agents.observations.flatten`): exteroception for the upper layer;
    without the lower layer ('flat') also proprioception; the lower layer
    itself ('lowlevel') proprioception and its command."""
    if self.agent == 'lowlevel':
      return obs_lib.LOWER_LAYER_PREFIXES
    return ('extero',) if self.uses_commands else ('proprio', 'extero')

  @property
  def carry_size(self) -> int:
    """C, the carry width of actor and learner: the middle layer's state,
    then a separate critic's (2H); one width for every variant, carried but
    unused without memory."""
    separate_critic = self.critic == 'separate' and self.uses_commands
    return self.middle_layer_size * (2 if separate_critic else 1)

  def __post_init__(self):
    if self.agent == 'lowlevel':  # The controller's format (see the field).
      object.__setattr__(self, 'state_dependent_std', True)
    # Lists from a CLI or JSON become tuples, keeping the config hashable.
    for name in ('upper_layer_sizes', 'head_sizes', 'critic_sizes',
                 'flat_sizes'):
      object.__setattr__(self, name, tuple(getattr(self, name)))
    fields.check(self)
    if self.initial_action_std:
      if self.state_dependent_std:
        raise ValueError('--initial-action-std needs a state-independent std '
                         '(--no-state-dependent-std; the head outputs it '
                         f'otherwise), got agent={self.agent!r}.')
      if self.initial_action_std <= self.min_action_std:
        raise ValueError(
            f'--initial-action-std must be > --min-action-std '
            f'({self.min_action_std}), got {self.initial_action_std}.')
