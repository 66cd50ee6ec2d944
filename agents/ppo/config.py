"""PPO hyper-parameters, one frozen dataclass passed whole.

Defaults follow Brax's and CleanRL's continuous-control PPO; the paper's
hierarchy starts from Adam lr 5e-4 and discount 0.995 (set them explicitly).
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

  def __post_init__(self):
    positive = ('learning_rate', 'adam_epsilon', 'clip_epsilon',
                'max_grad_norm', 'num_epochs', 'num_minibatches',
                'reward_scaling', 'observation_clip')
    for name in positive:
      if not getattr(self, name) > 0:
        raise ValueError(f'PPOConfig.{name} must be > 0, got '
                         f'{getattr(self, name)!r}.')
    for name in ('discount', 'gae_lambda'):
      if not 0.0 <= getattr(self, name) <= 1.0:
        raise ValueError(f'PPOConfig.{name} must be in [0, 1], got '
                         f'{getattr(self, name)!r}.')
    for name in ('entropy_cost', 'value_cost'):
      if getattr(self, name) < 0:
        raise ValueError(f'PPOConfig.{name} must be >= 0, got '
                         f'{getattr(self, name)!r}.')
    # Lists from a CLI or JSON become tuples, keeping the config hashable.
    object.__setattr__(self, 'policy_hidden', tuple(self.policy_hidden))
    object.__setattr__(self, 'value_hidden', tuple(self.value_hidden))
