"""Proximal Policy Optimisation (Schulman et al. 2017), Acme-style layout.

One learner for every policy (`agents.hierarchy` builds its networks,
actors and learners, the lower layer's 'lowlevel' variant included), a
feed-forward network being a recurrent one without memory.

config.py    PPOConfig (a controller's record of the lower layer's settings
             and networks).
types.py     SequenceBatch (what actors send) and the loss's training batches.
losses.py    compute_gae and ppo_loss, pure functions over [T, B] arrays.
returns.py   compute_targets: truncation, GAE and value normalisation.
step_size.py Adam with a KL-adaptive learning rate.
learning.py  TrainingState, the jitted recurrent update and the PPOLearner.
"""
