"""Proximal Policy Optimisation (Schulman et al. 2017), Acme-style layout.

One learner for every policy: the lower layer's feed-forward one (this
package's actor and builder) and the hierarchy's (`agents.hierarchy`), a
feed-forward network being a recurrent one without memory.

config.py    PPOConfig, the lower layer's hyper-parameters.
types.py     SequenceBatch (what actors send) and the loss's training batches.
losses.py    compute_gae and ppo_loss, pure functions over [T, B] arrays.
returns.py   compute_targets: truncation, GAE and value normalisation.
step_size.py Adam with a KL-adaptive learning rate.
learning.py  TrainingState, the jitted recurrent update and the PPOLearner.
acting.py    PPOActor: batched feed-forward acting that records batches.
builder.py   PPOBuilder: config -> networks -> learner / actor.
"""
