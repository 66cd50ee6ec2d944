"""PPO's pure loss functions: GAE and the clipped surrogate objective.

No networks here: the loss receives the network outputs, so the feed-forward
learner and a recurrent one (which unrolls a GRU to get the same outputs)
share it. Shapes are time-major [T, B]; `ppo_loss` accepts any leading shape.
"""
import jax
import jax.numpy as jnp

from agents.networks import distributions
from agents.ppo import types


def compute_gae(
    rewards: jax.Array,
    values: jax.Array,
    discounts: jax.Array,
    bootstrap_value: jax.Array,
    lambda_: float,
) -> tuple[jax.Array, jax.Array]:
  """Generalised advantage estimation (Schulman et al. 2016).

  delta_t = r_t + d_t * V_{t+1} - V_t
  A_t = delta_t + d_t * lambda * A_{t+1},   A_T = 0
  with V_T = bootstrap_value. A backward `lax.scan` evaluates the recursion.

  Args:
    rewards: [T, B] rewards r_t.
    values: [T, B] value estimates V_t of the observation before step t.
    discounts: [T, B] d_t = gamma * (1 - terminated_t): 0 cuts both the
      bootstrap and the trace at an episode's end. Truncated episodes are the
      caller's business (see `types.SequenceBatch.truncation`).
    bootstrap_value: [B] V_T, the value after the last step.
    lambda_: GAE lambda in [0, 1].

  Returns:
    (advantages [T, B], returns [T, B] = advantages + values); both are
    constants for autodiff.
  """
  next_values = jnp.concatenate([values[1:], bootstrap_value[None]], axis=0)
  deltas = rewards + discounts * next_values - values

  def backward_step(next_advantage, delta_and_discount):
    delta, discount = delta_and_discount
    advantage = delta + discount * lambda_ * next_advantage
    return advantage, advantage

  _, advantages = jax.lax.scan(
      backward_step, jnp.zeros_like(bootstrap_value), (deltas, discounts),
      reverse=True)
  advantages = jax.lax.stop_gradient(advantages)
  returns = jax.lax.stop_gradient(advantages + values)
  return advantages, returns


def ppo_loss(
    dist_params: jax.Array,
    values: jax.Array,
    batch: types.TrainingBatch,
    distribution: distributions.NormalTanhDistribution,
    entropy_key: jax.Array,
    *,
    clip_epsilon: float = 0.2,
    clip_value_loss: bool = False,
    entropy_cost: float = 1e-2,
    value_cost: float = 0.5,
    normalize_advantages: bool = True,
) -> tuple[jax.Array, dict[str, jax.Array]]:
  """Clipped surrogate + value regression - entropy bonus.

  Args:
    dist_params: [..., 2A] current policy output on batch.observation.
    values: [...] current value estimates on batch.observation.
    batch: rollout-derived inputs, leading shape [...] (see TrainingBatch).
    distribution: reads `dist_params`.
    entropy_key: PRNG key of the entropy's one-sample estimate.
    clip_epsilon, clip_value_loss, entropy_cost, value_cost,
    normalize_advantages: see `PPOConfig`.

  Returns:
    (scalar loss, metrics dict of scalars): total_loss, policy_loss,
    value_loss, entropy, approx_kl (the low-variance k3 estimator of
    KL(behaviour || current)), clip_fraction and action_std (the mean
    pre-tanh standard deviation).
  """
  advantages = batch.advantage
  if normalize_advantages:
    advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)

  log_prob = distribution.log_prob(dist_params, batch.raw_action)
  log_ratio = log_prob - batch.behaviour_log_prob
  ratio = jnp.exp(log_ratio)
  clipped_ratio = jnp.clip(ratio, 1.0 - clip_epsilon, 1.0 + clip_epsilon)
  policy_loss = -jnp.mean(
      jnp.minimum(ratio * advantages, clipped_ratio * advantages))

  value_error = batch.target_value - values
  value_loss = 0.5 * jnp.square(value_error)
  if clip_value_loss:
    clipped_values = batch.behaviour_value + jnp.clip(
        values - batch.behaviour_value, -clip_epsilon, clip_epsilon)
    value_loss = jnp.maximum(
        value_loss, 0.5 * jnp.square(batch.target_value - clipped_values))
  value_loss = jnp.mean(value_loss)

  entropy = jnp.mean(distribution.entropy(dist_params, entropy_key))
  total_loss = policy_loss + value_cost * value_loss - entropy_cost * entropy

  metrics = {
      'total_loss': total_loss,
      'policy_loss': policy_loss,
      'value_loss': value_loss,
      'entropy': entropy,
      'approx_kl': jnp.mean((ratio - 1.0) - log_ratio),
      'clip_fraction': jnp.mean(
          (jnp.abs(ratio - 1.0) > clip_epsilon).astype(jnp.float32)),
      'action_std': jnp.mean(distribution.loc_and_scale(dist_params)[1]),
  }
  return total_loss, metrics
