"""PPO hyper-parameters of a feed-forward policy, one frozen dataclass, and
the checks every PPO config shares.

A controller's config.json records the lower layer's settings and network
sizes as a PPOConfig (`agents.lowlevel.controller` rebuilds its policy from
it); the lower layer trains as the 'lowlevel' variant of
`agents.hierarchy.config.HierarchyConfig`, which has the same optimisation
and objective fields, so one learner (`agents.ppo.learning`) reads either.
Defaults follow Brax's and CleanRL's continuous-control PPO.
"""
import dataclasses


@dataclasses.dataclass(frozen=True)
class PPOConfig:
  """Everything that decides how PPO learns."""

  learning_rate: float = 3e-4
  """Adam step size."""
  adam_epsilon: float = 1e-5
  """Adam's denominator epsilon (1e-5 as in CleanRL / PureJaxRL, not 1e-8)."""
  discount: float = 0.99
  """Per-step discount gamma; multiplied by the rollout's 0/1 discount."""
  gae_lambda: float = 0.95
  """GAE lambda: 0 is one-step TD, 1 is Monte-Carlo returns."""
  clip_epsilon: float = 0.2
  """Trust region: probability ratios are clipped to [1 - eps, 1 + eps]."""
  clip_value_loss: bool = False
  """Also clip value updates to +-clip_epsilon around the rollout's values
  (CleanRL's option). Off by default, as in Brax: with unnormalised returns
  the clip mostly slows the critic down."""
  entropy_cost: float = 1e-2
  """Weight of the entropy bonus (subtracted from the loss)."""
  value_cost: float = 0.5
  """Weight of the value loss 0.5 * (return - value)^2."""
  max_grad_norm: float = 0.5
  """Gradients are rescaled to at most this global L2 norm."""
  num_epochs: int = 4
  """Passes over each rollout."""
  num_minibatches: int = 4
  """Minibatches per epoch; the rollout's batch axis B must divide by it."""
  normalize_advantages: bool = True
  """Standardise advantages within each minibatch."""
  reward_scaling: float = 1.0
  """Rewards are multiplied by this before GAE (Brax's reward_scaling)."""
  normalize_observations: bool = True
  """Standardise observations with running statistics
  (`agents.normalization`)."""
  observation_clip: float = 5.0
  """Normalised observations are clipped to [-clip, clip]."""
  seed: int = 0
  """Seed of the learner's parameter initialisation and minibatch shuffling."""
  policy_hidden: tuple[int, ...] = (256, 256)
  """Hidden layer widths of the policy MLP."""
  value_hidden: tuple[int, ...] = (256, 256)
  """Hidden layer widths of the value MLP."""
  activation: str = 'swish'
  """Hidden activation of both MLPs, by name (see `agents.networks.mlp`)."""

  @property
  def target_kl(self) -> float:
    """0: a constant learning rate (Brax's settings for the lower layer; the
    KL-adaptive rate is `HierarchyConfig.target_kl`)."""
    return 0.0

  @property
  def normalize_values(self) -> bool:
    """False: the critic predicts (scaled) returns directly."""
    return False

  def __post_init__(self):
    validate(self)
    # Lists from a CLI or JSON become tuples, keeping the config hashable.
    object.__setattr__(self, 'policy_hidden', tuple(self.policy_hidden))
    object.__setattr__(self, 'value_hidden', tuple(self.value_hidden))


def validate(config, positive: tuple[str, ...] = (),
             non_negative: tuple[str, ...] = ()) -> None:
  """Checks the PPO fields of a config (`PPOConfig`, `HierarchyConfig`).

  Args:
    config: a config with PPOConfig's optimisation and objective fields.
    positive, non_negative: the config's own further fields to check.

  Raises:
    ValueError naming `<config class>.<field>` and the bad value.
  """
  name_of = lambda field: f'{type(config).__name__}.{field}'
  for field in ('learning_rate', 'adam_epsilon', 'clip_epsilon',
                'max_grad_norm', 'num_epochs', 'num_minibatches',
                'reward_scaling', 'observation_clip', *positive):
    if not getattr(config, field) > 0:
      raise ValueError(f'{name_of(field)} must be > 0, got '
                       f'{getattr(config, field)!r}.')
  for field in ('discount', 'gae_lambda'):
    if not 0.0 <= getattr(config, field) <= 1.0:
      raise ValueError(f'{name_of(field)} must be in [0, 1], got '
                       f'{getattr(config, field)!r}.')
  for field in ('entropy_cost', 'value_cost', 'target_kl', *non_negative):
    if getattr(config, field) < 0:
      raise ValueError(f'{name_of(field)} must be >= 0, got '
                       f'{getattr(config, field)!r}.')
