"""A plain Flax MLP torso, the building block of every feed-forward network.

Activations are named by strings so that configs stay plain, serialisable data
(a config records `'swish'`, not a function object).
"""
from typing import Callable, Sequence

import flax.linen as nn
import jax

ACTIVATIONS: dict[str, Callable[[jax.Array], jax.Array]] = {
    'relu': nn.relu,
    'tanh': nn.tanh,
    'swish': nn.swish,  # Brax's default for its PPO locomotion networks.
    'elu': nn.elu,
    'gelu': nn.gelu,
}


def get_activation(name: str) -> Callable[[jax.Array], jax.Array]:
  """The activation function called `name`; ValueError names the options."""
  try:
    return ACTIVATIONS[name]
  except KeyError:
    raise ValueError(f'Unknown activation {name!r}; expected one of '
                     f'{sorted(ACTIVATIONS)}.') from None


class MLP(nn.Module):
  """Dense layers `layer_sizes`, activation between them.

  Attributes:
    layer_sizes: output width of each Dense layer, the last one included.
    activation: name of the activation (see `ACTIVATIONS`).
    activate_final: also apply the activation after the last layer (true for
      a torso feeding another module, false for an output head).
    final_kernel_scale: variance scale of the last layer's initialiser. A
      small value (e.g. 0.01 for a policy head) starts the policy close to its
      prior, a known help for PPO (Andrychowicz et al. 2021).

  Input [..., in_dim] -> output [..., layer_sizes[-1]].
  """
  layer_sizes: Sequence[int]
  activation: str = 'swish'
  activate_final: bool = False
  final_kernel_scale: float = 1.0

  @nn.compact
  def __call__(self, x: jax.Array) -> jax.Array:
    activation = get_activation(self.activation)
    last = len(self.layer_sizes) - 1
    for i, size in enumerate(self.layer_sizes):
      scale = self.final_kernel_scale if i == last else 1.0
      x = nn.Dense(
          size,
          kernel_init=nn.initializers.variance_scaling(
              scale, 'fan_in', 'uniform'),
          name=f'dense_{i}')(x)
      if i < last or self.activate_final:
        x = activation(x)
    return x

