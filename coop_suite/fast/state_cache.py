"""`StateCache`: values computed once per physics state."""


class StateCache:
  """Values of the current physics state, each computed once.

  The state is that of one mjData (`bind`). A value is kept until
  `invalidate()` (called by the task at each step and reset, and by
  whoever edits the physics by hand) or until the simulation time moves on
  outside `step`. Disabled, it keeps nothing and `get` always computes:
  plain composer calls every observable on its own.
  """

  def __init__(self, enabled=True):
    self.enabled = enabled
    self._data = None
    self._version = 0
    self._key = None
    self._values = {}

  def bind(self, data):
    """Keys the cache on `data` (an `mujoco.MjData`) from now on."""
    self._data = data
    self.invalidate()

  def invalidate(self):
    """Forgets every value: the state has changed."""
    self._version += 1

  def get(self, name, compute):
    """The value `name` of this state: `compute()` on first use."""
    if not self.enabled:
      return compute()
    # Read from the mjData itself: dm_control's wrappers cost more.
    key = (self._version, self._data.time)
    if key != self._key:
      self._key = key
      self._values = {}
    try:
      return self._values[name]
    except KeyError:
      value = self._values[name] = compute()
      return value
