"""Hyper-parameters of the hierarchical agent, one frozen dataclass.

Defaults are the paper's where it gives them (section 5: IPPO, Adam lr 5e-4,
PPO clip 0.2, discount 0.995); the others follow PureJaxRL's `ppo_rnn` and the
project's PPO (`agents.ppo.config`). One config describes one species; the
runner makes a learner and actor per species.
"""
import dataclasses

AGENTS = ('hrl', 'no_memory', 'flat', 'mappo')


@dataclasses.dataclass(frozen=True)
class HierarchyConfig:
  """Everything that decides the agent's networks and how they learn."""

  agent: str = 'hrl'
  """Variant (paper section 6 ablations): 'hrl' = UL MLP + ML GRU (default);
  'no_memory' = an MLP in place of the GRU (Nachum et al. 2019); 'flat' = one
  MLP from proprio + extero to the joint actions, no lower layer; 'mappo' =
  'hrl' whose value head reads the global state (centralised critic)."""

  # Optimisation.
  learning_rate: float = 5e-4
  """Adam step size (paper)."""
  adam_epsilon: float = 1e-5
  """Adam's denominator epsilon (CleanRL / PureJaxRL)."""
  max_grad_norm: float = 0.5
  """Gradients are rescaled to at most this global L2 norm."""
  num_epochs: int = 4
  """Passes over each batch of sequences."""
  num_minibatches: int = 4
  """Minibatches per epoch, split along the batch axis B (sequences stay
  whole), which must divide by it."""

  # PPO objective.
  discount: float = 0.995
  """Per-command discount gamma (paper); multiplied by the 0/1 env discount.
  Per command, not per low-level step: with a 0.5 s command period the horizon
  1 / (1 - gamma) is 200 commands = 100 s."""
  gae_lambda: float = 0.95
  """GAE lambda: 0 is one-step TD, 1 is Monte-Carlo returns."""
  clip_epsilon: float = 0.2
  """PPO trust region: ratios clipped to [1 - eps, 1 + eps] (paper)."""
  clip_value_loss: bool = False
  """Also clip value updates to +-clip_epsilon (CleanRL's option)."""
  entropy_cost: float = 1e-3
  """Weight of the entropy bonus. The paper gives none; 1e-3 (ten times below
  the lower layer's 1e-2) because the command has only 2 dimensions and a
  state-independent std, which a larger bonus keeps wide for too long."""
  value_cost: float = 0.5
  """Weight of the value loss 0.5 * (return - value)^2."""
  normalize_advantages: bool = True
  """Standardise advantages within each minibatch."""
  reward_scaling: float = 0.01
  """Rewards are multiplied by this before GAE. The paper's rewards summed
  over a 0.5 s command reach ~40 per command and ~3000 per episode; unscaled,
  the value loss (~3e4) dominates the clipped global gradient norm and the
  policy barely moves (measured: approx_kl ~1e-4 per update)."""

  # Data.
  sequence_length: int = 16
  """T, commands per training sequence (truncated BPTT length): the actor
  hands over a `SequenceBatch` every T commands, its GRU state stored at the
  start of the sequence. 16 commands = 8 s at a 0.5 s command period."""
  normalize_observations: bool = True
  """Standardise observations and the global state with running statistics
  (`agents.normalization`), updated by the learner before each update."""
  observation_clip: float = 5.0
  """Normalised inputs are clipped to [-clip, clip]."""
  seed: int = 0
  """Seed of parameter initialisation, minibatch shuffling and action noise
  (the builder folds in the species and actor ids)."""

  # Networks.
  upper_layer_sizes: tuple[int, ...] = (128, 128)
  """UL: hidden widths of the MLP over the exteroceptive features."""
  middle_layer_size: int = 128
  """ML: GRU hidden size h ('hrl', 'mappo'), or the width of the MLP layer
  replacing it ('no_memory'). Also the carry width of every variant, so that
  actor and learner handle one carry shape."""
  head_sizes: tuple[int, ...] = (128,)
  """Hidden widths of the command head and the value head on top of the ML
  (PureJaxRL's separate actor / critic MLPs after the shared GRU)."""
  critic_sizes: tuple[int, ...] = (128, 128)
  """'mappo': hidden widths of the centralised critic MLP over the global
  state."""
  flat_sizes: tuple[int, ...] = (256, 256)
  """'flat': hidden widths of its policy MLP and its separate value MLP (the
  lower layer's own architecture, `agents.ppo` defaults)."""
  activation: str = 'swish'
  """Hidden activation of all MLPs, by name (see `agents.networks.mlp`)."""
  state_dependent_std: bool = False
  """False: the action std is a learned parameter vector, the same for every
  state (PureJaxRL); exploration then cannot collapse in some states while
  the value is still poor. True: the head outputs it (Brax). Both start at
  softplus(0) + 1e-3 ~= 0.69 in pre-tanh units."""

  @property
  def recurrent(self) -> bool:
    """Whether the middle layer carries a hidden state between commands."""
    return self.agent in ('hrl', 'mappo')

  @property
  def observation_prefixes(self) -> tuple[str, ...]:
    """Observation groups the networks read, in flattening order (see
    `agents.observations.flatten`): exteroception for the upper layer;
    'flat' has no lower layer, so it also reads proprioception."""
    return ('proprio', 'extero') if self.agent == 'flat' else ('extero',)

  @property
  def uses_global_state(self) -> bool:
    """Whether the value head reads a `global_state` input."""
    return self.agent == 'mappo'

  def __post_init__(self):
    if self.agent not in AGENTS:
      raise ValueError(f'HierarchyConfig.agent must be one of {AGENTS}, got '
                       f'{self.agent!r}.')
    positive = ('learning_rate', 'adam_epsilon', 'clip_epsilon',
                'max_grad_norm', 'num_epochs', 'num_minibatches',
                'reward_scaling', 'observation_clip', 'sequence_length',
                'middle_layer_size')
    for name in positive:
      if not getattr(self, name) > 0:
        raise ValueError(f'HierarchyConfig.{name} must be > 0, got '
                         f'{getattr(self, name)!r}.')
    for name in ('discount', 'gae_lambda'):
      if not 0.0 <= getattr(self, name) <= 1.0:
        raise ValueError(f'HierarchyConfig.{name} must be in [0, 1], got '
                         f'{getattr(self, name)!r}.')
    for name in ('entropy_cost', 'value_cost'):
      if getattr(self, name) < 0:
        raise ValueError(f'HierarchyConfig.{name} must be >= 0, got '
                         f'{getattr(self, name)!r}.')
    # Lists from a CLI or JSON become tuples, keeping the config hashable.
    for name in ('upper_layer_sizes', 'head_sizes', 'critic_sizes',
                 'flat_sizes'):
      object.__setattr__(self, name, tuple(getattr(self, name)))
