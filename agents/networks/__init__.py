"""Network building blocks shared by the agents.

mlp.py            Flax MLP torso.
distributions.py  tanh-squashed diagonal Gaussian, pure functions of its params.
policy_value.py   feed-forward policy and value networks.
"""
