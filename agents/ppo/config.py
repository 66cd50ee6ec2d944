"""PPO hyper-parameters of a feed-forward policy, one frozen dataclass
passed whole.

A controller's config.json records the lower layer's settings and network
sizes as a PPOConfig (`agents.lowlevel.controller` rebuilds its policy from
it); the lower layer trains as the 'lowlevel' variant of
`agents.hierarchy.config.HierarchyConfig`, which has the same optimisation
and objective fields, so one learner (`agents.ppo.learning`) reads either.
Defaults follow Brax's and CleanRL's continuous-control PPO. Each field
declares its allowed values (`agents.fields`).
"""
import dataclasses

from agents import fields


@dataclasses.dataclass(frozen=True)
class PPOConfig:
  """Everything that decides how PPO learns."""

  learning_rate: float = fields.field(3e-4, fields.POSITIVE)
  """Adam step size."""
  adam_epsilon: float = fields.field(1e-5, fields.POSITIVE)
  """Adam's denominator epsilon (1e-5 as in CleanRL / PureJaxRL, not 1e-8)."""
  discount: float = fields.field(0.99, fields.UNIT)
  """Per-step discount gamma; multiplied by the rollout's 0/1 discount."""
  gae_lambda: float = fields.field(0.95, fields.UNIT)
  """GAE lambda: 0 is one-step TD, 1 is Monte-Carlo returns."""
  clip_epsilon: float = fields.field(0.2, fields.POSITIVE)
  """Trust region: probability ratios are clipped to [1 - eps, 1 + eps]."""
  clip_value_loss: bool = False
  """Also clip value updates to +-clip_epsilon around the rollout's values
  (CleanRL's option). Off by default, as in Brax: with unnormalised returns
  the clip mostly slows the critic down."""
  entropy_cost: float = fields.field(1e-2, fields.NON_NEGATIVE)
  """Weight of the entropy bonus (subtracted from the loss)."""
  value_cost: float = fields.field(0.5, fields.NON_NEGATIVE)
  """Weight of the value loss 0.5 * (return - value)^2."""
  max_grad_norm: float = fields.field(0.5, fields.POSITIVE)
  """Gradients are rescaled to at most this global L2 norm."""
  num_epochs: int = fields.field(4, fields.COUNT)
  """Passes over each rollout."""
  num_minibatches: int = fields.field(4, fields.COUNT)
  """Minibatches per epoch; the rollout's batch axis B must divide by it."""
  normalize_advantages: bool = True
  """Standardise advantages within each minibatch."""
  reward_scaling: float = fields.field(1.0, fields.POSITIVE)
  """Rewards are multiplied by this before GAE (Brax's reward_scaling)."""
  normalize_observations: bool = True
  """Standardise observations with running statistics
  (`agents.normalization`)."""
  observation_clip: float = fields.field(5.0, fields.POSITIVE)
  """Normalised observations are clipped to [-clip, clip]."""
  seed: int = fields.field(0, fields.SEED)
  """Seed of the learner's parameter initialisation and minibatch shuffling."""
  policy_hidden: tuple[int, ...] = fields.field((256, 256), fields.COUNT)
  """Hidden layer widths of the policy MLP."""
  value_hidden: tuple[int, ...] = fields.field((256, 256), fields.COUNT)
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
    fields.check(self)
    # Lists from a CLI or JSON become tuples, keeping the config hashable.
    object.__setattr__(self, 'policy_hidden', tuple(self.policy_hidden))
    object.__setattr__(self, 'value_hidden', tuple(self.value_hidden))
