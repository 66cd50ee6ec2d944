"""Running observation statistics against numpy over several batches."""
import jax
import numpy as np

from agents import normalization


def test_matches_numpy_over_batches_of_different_shapes():
  rng = np.random.default_rng(0)
  batches = [rng.normal(3.0, 2.0, size=(4, 5, 3)),  # [T, B, dim]
             rng.normal(-1.0, 0.5, size=(7, 3)),  # [N, dim]
             rng.normal(10.0, 4.0, size=(1, 3))]
  state = normalization.init(3)
  update = jax.jit(normalization.update)
  for batch in batches:
    state = update(state, batch.astype(np.float32))

  everything = np.concatenate([b.reshape(-1, 3) for b in batches])
  assert float(state.count) == len(everything)
  np.testing.assert_allclose(state.mean, everything.mean(0), rtol=1e-5)
  np.testing.assert_allclose(state.var, everything.var(0), rtol=1e-5)

  normalized = normalization.normalize(state, everything, clip=100.0)
  np.testing.assert_allclose(normalized.mean(0), 0.0, atol=1e-4)
  np.testing.assert_allclose(normalized.std(0), 1.0, rtol=1e-4)
  assert np.max(np.abs(normalization.normalize(state, everything * 1e3))) <= 5.0


def test_fresh_statistics_are_the_identity_and_disabled_passes_through():
  x = np.array([[0.5, -2.0]], np.float32)
  np.testing.assert_allclose(normalization.normalize(normalization.init(2), x),
                             x, rtol=1e-6)
  passthrough = normalization.make_preprocess_fn(enabled=False)
  np.testing.assert_array_equal(passthrough(normalization.init(2), x * 100),
                                x * 100)


def test_round_trips_through_npz(tmp_path):
  state = normalization.update(
      normalization.init(4), np.arange(20, dtype=np.float32).reshape(5, 4))
  path = tmp_path / 'weights.npz'
  np.savez(path, policy_kernel=np.ones(3),
           **normalization.to_dict(state, prefix='normalizer/'))
  with np.load(path) as arrays:
    restored = normalization.from_dict(arrays, prefix='normalizer/')
  for name in normalization.NormalizerState._fields:
    np.testing.assert_array_equal(getattr(restored, name), getattr(state, name))
  np.testing.assert_array_equal(
      normalization.from_dict(normalization.to_dict(state)).mean, state.mean)
