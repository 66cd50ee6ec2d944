"""Acme-style JAX agents for coop-suite (jax, flax, optax; no MuJoCo here).

Layout, one concept per module:
  core.py           Actor / Learner / VariableSource interfaces.
  normalization.py  running observation statistics saved with the weights.
  networks/         Flax MLP torso, tanh-Gaussian head, policy/value networks.
  ppo/              config, losses, learner, actor and the builder wiring them.

Importing `agents` is cheap: submodules import JAX only when they are imported.
"""
