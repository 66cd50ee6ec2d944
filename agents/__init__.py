"""Acme-style JAX agents for coop-suite (jax, flax, optax; no MuJoCo here).

Layout, one concept per module:
  core.py           Actor / Learner / VariableSource interfaces.
  checkpointing.py  a learner's saved state (kind, format, state dict).
  fields.py         config fields with their allowed values; the one check.
  normalization.py  running statistics (observations, global state, values).
  observations.py   observation dicts -> the flat vectors the networks read.
  networks/         Flax MLP torso, tanh-Gaussian head, feed-forward
                    policy/value networks.
  ppo/              the one PPO learner (recurrent; feed-forward = without
                    memory), its losses, returns, step size, data types, and
                    the lower layer's config, actor and builder.
  hierarchy/        the cooperative agent: upper and middle layer, variants.
  lowlevel/         the frozen lower layer (pretrained walker) and the
                    CommandWrapper that steps it.

Importing `agents` is cheap: submodules import JAX only when they are imported.
"""
