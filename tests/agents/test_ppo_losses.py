"""GAE and the PPO loss against hand arithmetic."""
import math

import jax
import jax.numpy as jnp
import numpy as np

from agents.networks import distributions
from agents.ppo import losses
from agents.ppo import types


def test_gae_three_steps_with_termination_in_the_middle():
  # Column 0: gamma = 0.9, lambda = 0.5, the episode terminates at step 1,
  # so d = [0.9, 0, 0.9] and step 2 belongs to the next episode.
  #   next values V_{t+1} = [1.0, 1.5, 2.0]  (2.0 is the bootstrap value)
  #   delta_0 = 1 + 0.9 * 1.0 - 0.5 = 1.4
  #   delta_1 = 2 + 0.0 * 1.5 - 1.0 = 1.0    (no bootstrap across the end)
  #   delta_2 = 3 + 0.9 * 2.0 - 1.5 = 3.3
  #   A_2 = 3.3
  #   A_1 = 1.0 + 0.0 * 0.5 * 3.3 = 1.0      (trace cut)
  #   A_0 = 1.4 + 0.9 * 0.5 * 1.0 = 1.85
  #   returns = A + V = [2.35, 2.0, 4.8]
  # Column 1: no termination, rewards [0, 0, 1], values and bootstrap 0:
  #   deltas [0, 0, 1]; A_2 = 1, A_1 = 0.45 * 1 = 0.45, A_0 = 0.45^2 = 0.2025.
  rewards = jnp.array([[1.0, 0.0], [2.0, 0.0], [3.0, 1.0]])
  values = jnp.array([[0.5, 0.0], [1.0, 0.0], [1.5, 0.0]])
  discounts = jnp.array([[0.9, 0.9], [0.0, 0.9], [0.9, 0.9]])
  bootstrap_value = jnp.array([2.0, 0.0])

  advantages, returns = jax.jit(losses.compute_gae, static_argnums=4)(
      rewards, values, discounts, bootstrap_value, 0.5)

  np.testing.assert_allclose(
      advantages, [[1.85, 0.2025], [1.0, 0.45], [3.3, 1.0]], rtol=1e-6)
  np.testing.assert_allclose(
      returns, [[2.35, 0.2025], [2.0, 0.45], [4.8, 1.0]], rtol=1e-6)


def test_gae_with_lambda_one_is_the_discounted_return_minus_value():
  rewards = jnp.array([[1.0], [1.0], [1.0]])
  values = jnp.array([[0.3], [0.2], [0.1]])
  discounts = jnp.full((3, 1), 0.5)
  _, returns = losses.compute_gae(rewards, values, discounts,
                                  jnp.array([4.0]), 1.0)
  # G_0 = 1 + 0.5 + 0.25 + 0.125 * 4 = 2.25
  np.testing.assert_allclose(returns[0, 0], 2.25, rtol=1e-6)


def _batch(log_prob_shift, advantage, dist, dist_params, raw_action):
  log_prob = dist.log_prob(dist_params, raw_action)
  return types.TrainingBatch(
      observation=jnp.zeros((2, 1)), raw_action=raw_action,
      behaviour_log_prob=log_prob - log_prob_shift,
      behaviour_value=jnp.zeros(2), advantage=advantage,
      target_value=jnp.array([1.0, 3.0]))


def test_ppo_loss_clips_the_ratio_and_regresses_values():
  dist = distributions.NormalTanhDistribution(action_size=1)
  dist_params = jnp.array([[0.1, 0.0], [-0.2, 0.3]])
  raw_action = jnp.array([[0.4], [-0.1]])
  values = jnp.zeros(2)
  kwargs = dict(entropy_cost=0.0, value_cost=1.0, normalize_advantages=False)
  key = jax.random.PRNGKey(0)

  # Ratio 1.5 on both samples. Advantage +1: min(1.5, 1.2) = 1.2 -> loss -1.2.
  # Advantage -1: min(-1.5, -1.2) = -1.5 -> loss 1.5. Mean policy loss 0.15.
  batch = _batch(math.log(1.5), jnp.array([1.0, -1.0]), dist, dist_params,
                 raw_action)
  loss, metrics = losses.ppo_loss(dist_params, values, batch, dist, key,
                                  **kwargs)
  np.testing.assert_allclose(metrics['policy_loss'], 0.15, rtol=1e-5)
  # Value loss: 0.5 * mean([1^2, 3^2]) = 2.5.
  np.testing.assert_allclose(metrics['value_loss'], 2.5, rtol=1e-6)
  np.testing.assert_allclose(loss, 0.15 + 2.5, rtol=1e-5)
  np.testing.assert_allclose(metrics['clip_fraction'], 1.0)

  # On-policy (ratio 1): no clipping, zero KL.
  batch = _batch(0.0, jnp.array([1.0, -1.0]), dist, dist_params, raw_action)
  _, metrics = losses.ppo_loss(dist_params, values, batch, dist, key, **kwargs)
  np.testing.assert_allclose(metrics['approx_kl'], 0.0, atol=1e-7)
  np.testing.assert_allclose(metrics['clip_fraction'], 0.0)


def test_clipped_value_loss_keeps_the_larger_error():
  dist = distributions.NormalTanhDistribution(action_size=1)
  dist_params = jnp.zeros((2, 2))
  raw_action = jnp.zeros((2, 1))
  batch = _batch(0.0, jnp.zeros(2), dist, dist_params, raw_action)
  # Values moved from 0 to 2 (targets 1, 3); clipped to 0.2:
  # sample 0: max(0.5 * 1^2, 0.5 * 0.8^2) = 0.5
  # sample 1: max(0.5 * 1^2, 0.5 * 2.8^2) = 3.92; mean 2.21.
  _, metrics = losses.ppo_loss(
      dist_params, jnp.array([2.0, 2.0]), batch, dist, jax.random.PRNGKey(0),
      clip_value_loss=True, normalize_advantages=False)
  np.testing.assert_allclose(metrics['value_loss'], 2.21, rtol=1e-5)
