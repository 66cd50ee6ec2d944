"""The tanh-squashed Gaussian against numpy change-of-variables arithmetic."""
import jax
import jax.numpy as jnp
import numpy as np

from agents.networks import distributions


def _numpy_log_prob(loc, scale, action):
  # p_A(a) = N(atanh(a); loc, scale) * |d atanh(a) / da|,
  # with d atanh(a) / da = 1 / (1 - a^2).
  u = np.arctanh(action)
  gaussian = (-0.5 * ((u - loc) / scale) ** 2 - np.log(scale)
              - 0.5 * np.log(2 * np.pi))
  return np.sum(gaussian - np.log1p(-action ** 2), axis=-1)


def test_log_prob_matches_change_of_variables():
  dist = distributions.NormalTanhDistribution(action_size=3)
  rng = np.random.default_rng(0)
  dist_params = rng.normal(size=(5, 6)).astype(np.float32)
  raw_action = rng.normal(size=(5, 3)).astype(np.float64)
  loc, scale = map(np.asarray, dist.loc_and_scale(jnp.asarray(dist_params)))

  ours = dist.log_prob(jnp.asarray(dist_params), jnp.asarray(raw_action))
  expected = _numpy_log_prob(loc, scale, np.tanh(raw_action))
  np.testing.assert_allclose(ours, expected, rtol=1e-4, atol=1e-4)


def test_density_integrates_to_one_over_the_squashed_interval():
  dist = distributions.NormalTanhDistribution(action_size=1)
  dist_params = jnp.array([0.7, -0.5])  # loc 0.7, scale softplus(-0.5).
  actions = np.linspace(-1.0, 1.0, 200_001)[1:-1]
  raw = jnp.asarray(np.arctanh(actions)[:, None], jnp.float32)
  density = np.exp(np.asarray(dist.log_prob(dist_params, raw), np.float64))
  np.testing.assert_allclose(np.trapezoid(density, actions), 1.0, atol=2e-3)


def test_entropy_estimate_matches_monte_carlo():
  dist = distributions.NormalTanhDistribution(action_size=2)
  dist_params = jnp.array([0.5, -1.0, 0.2, 0.4])
  keys = jax.random.split(jax.random.PRNGKey(1), 20_000)
  estimate = jnp.mean(jax.vmap(lambda k: dist.entropy(dist_params, k))(keys))
  raw = jax.vmap(lambda k: dist.sample_raw(dist_params, k))(keys)
  monte_carlo = -jnp.mean(dist.log_prob(dist_params, raw))
  np.testing.assert_allclose(estimate, monte_carlo, atol=0.03)


def test_samples_stay_in_bounds_and_rescale_to_the_spec():
  dist = distributions.NormalTanhDistribution(action_size=2)
  dist_params = jnp.array([[30.0, -30.0, 3.0, 3.0], [0.0, 0.0, 5.0, -5.0]])
  tiled = jnp.tile(dist_params, (500, 1))
  raw = dist.sample_raw(tiled, jax.random.PRNGKey(2))
  action = dist.squash(raw)
  assert np.all(np.abs(action) <= 1.0)
  assert np.all(np.isfinite(dist.log_prob(tiled, raw)))

  low, high = np.array([-2.0, 0.0]), np.array([2.0, 0.5])
  scaled = distributions.rescale(action, low, high)
  assert np.all((scaled >= low) & (scaled <= high))
  np.testing.assert_allclose(
      distributions.rescale(jnp.array([-1.0, 0.0, 1.0]), 0.0, 4.0), [0, 2, 4])
  np.testing.assert_allclose(dist.squash(dist.mode_raw(dist_params))[0],
                             np.tanh([30.0, -30.0]))
