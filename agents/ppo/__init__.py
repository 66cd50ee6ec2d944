"""Proximal Policy Optimisation (Schulman et al. 2017), Acme-style layout.

config.py    PPOConfig, every hyper-parameter documented.
types.py     Rollout (what actors send) and TrainingBatch (what the loss reads).
losses.py    compute_gae and ppo_loss, pure functions over [T, B] arrays.
returns.py   compute_targets: truncation, GAE and value normalisation.
step_size.py Adam with a KL-adaptive learning rate.
learning.py  TrainingState, the jitted update and the PPOLearner.
acting.py    PPOActor: batched feed-forward acting that records rollouts.
builder.py   PPOBuilder: config -> networks -> learner / actor.
"""
