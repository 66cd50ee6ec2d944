"""The Ant walker: a quadruped robot with egocentric proprioception.

The body is dm_control's Ant (same geometry, masses and motors) built from a
trimmed MJCF (see `assets/ant.xml`). Its proprioception (`ProprioceptionReader`,
read for all agents at once by the tasks) is what the lower layer of the
hierarchy reads; it is identical in every task so that one pretrained walker
controller serves them all.

Frames: "egocentric" means the torso frame (x forward, y left, z up in the
torso's own orientation); "heading frame" means the world frame rotated by the
torso's yaw only, which is what planar commands and exteroception use.
"""

import os

from dm_control import composer
from dm_control import mjcf
from dm_env import specs
import numpy as np

from coop_suite import kernels

_XML_PATH = os.path.join(os.path.dirname(__file__), "assets", "ant.xml")

# Height of the torso centre when the ant stands on flat ground (metres).
STANDING_HEIGHT = 0.55
NUM_ACTUATORS = 8


class Ant(composer.Robot):
  """A quadruped Ant with 8 torque-controlled joints and actions in [-1, 1].

  It has no observables of its own: the tasks compute every agent's
  features at once (`coop_suite.tasks.base.CoopTask.features`).
  """

  def _build(self, name="ant", rgba=None):
    """Builds the Ant.

    Args:
      name: MJCF model name; it prefixes every element once attached.
      rgba: optional body colour, so that species or agents can be told apart
        in videos.
    """
    self._mjcf_root = mjcf.from_path(_XML_PATH)
    self._mjcf_root.model = name
    if rgba is not None:
      self._mjcf_root.asset.find("material", "self").rgba = rgba
    self._prev_action = np.zeros(NUM_ACTUATORS)
    self._joint_qpos_adr = None
    self._joint_dof_adr = None

  @property
  def mjcf_model(self):
    return self._mjcf_root

  @composer.cached_property
  def actuators(self):
    return tuple(self._mjcf_root.find_all("actuator"))

  @composer.cached_property
  def joints(self):
    return tuple(actuator.joint for actuator in self.actuators)

  @composer.cached_property
  def root_body(self):
    return self._mjcf_root.find("body", "torso")

  @composer.cached_property
  def action_spec(self):
    return specs.BoundedArray(
        shape=(NUM_ACTUATORS,), dtype=np.float64, minimum=-1.0, maximum=1.0,
        name="\t".join(a.name for a in self.actuators))

  @property
  def prev_action(self):
    return self._prev_action

  def share_action_buffer(self, buffer):
    """Makes `prev_action` a view of `buffer` (shape [8]).

    A task that writes every agent's controls in one call (instead of one
    `apply_action` per walker) passes a row of its [n, 8] action array, so
    that `prev_action` stays current.
    """
    if buffer.shape != (NUM_ACTUATORS,):
      raise ValueError(f"Action buffer must have shape ({NUM_ACTUATORS},), "
                       f"got {buffer.shape}.")
    self._prev_action = buffer

  @property
  def joint_ranges(self):
    """Joint limits, shape [8, 2] (radians)."""
    return np.array([j.range for j in self.joints], dtype=np.float64)

  def after_compile(self, physics, random_state):
    # Index arrays let observables read `physics.data` directly, which is much
    # cheaper than binding MJCF elements at every control step.
    joints = physics.bind(self.joints)
    self._joint_qpos_adr = np.array(joints.qposadr)
    self._joint_dof_adr = np.array(joints.dofadr)
    self._actuator_ids = np.array(physics.bind(self.actuators).element_id)
    self._torso_id = int(physics.bind(self.root_body).element_id)
    # The free joint sits on the attachment frame, the torso's parent body,
    # whose origin coincides with the torso's centre.
    frame_id = physics.model.body_parentid[self._torso_id]
    self._free_dof_adr = int(physics.model.body_dofadr[frame_id])
    self._joint_limits = np.array(physics.model.jnt_range[joints.element_id])

  def initialize_episode(self, physics, random_state):
    self._prev_action[:] = 0.0

  def apply_action(self, physics, action, random_state):
    physics.data.ctrl[self._actuator_ids] = action
    self._prev_action[:] = action

  # --- State accessors (world frame unless stated) -------------------------

  def torso_position(self, physics):
    """Torso centre, shape [3], world frame (metres)."""
    return physics.data.xpos[self._torso_id]

  def heading(self, physics):
    """Yaw of the torso's x axis in the world frame (radians)."""
    xmat = physics.data.xmat[self._torso_id]
    return np.arctan2(xmat[3], xmat[0])

  def world_velocity(self, physics):
    """Torso linear velocity, shape [3], world frame (m/s)."""
    return physics.data.qvel[self._free_dof_adr:self._free_dof_adr + 3]

  def upright(self, physics):
    """Cosine between the torso's z axis and the world's z axis."""
    return physics.data.xmat[self._torso_id][8]

  def joint_positions(self, physics):
    return physics.data.qpos[self._joint_qpos_adr]

  def joint_velocities(self, physics):
    return physics.data.qvel[self._joint_dof_adr]

  def joints_at_limit(self, physics, fraction=0.99):
    """Number of joints within `fraction` of their range's half-width."""
    q = self.joint_positions(physics)
    low, high = self._joint_limits[:, 0], self._joint_limits[:, 1]
    centre, half = (high + low) / 2, (high - low) / 2
    return int(np.sum(np.abs(q - centre) > fraction * half))


class ProprioceptionReader:
  """Reads the proprioception of a fixed set of compiled Ants, vectorised.

  The index arrays into `physics.data` are gathered once and one compiled
  kernel reads all Ants: tasks read every agent's proprioception at every
  control step, where per-walker indexing would cost more than the physics.
  The returned arrays are views of one new array, never of `physics.data`,
  so observations stay valid after later steps.
  """

  def __init__(self, walkers):
    # pylint: disable=protected-access
    self._torso = np.array([w._torso_id for w in walkers])
    self._qpos = np.stack([w._joint_qpos_adr for w in walkers])
    self._dof = np.stack([w._joint_dof_adr for w in walkers])
    self._free = np.array([w._free_dof_adr for w in walkers])
    self._bound = (None, None)  # (an mjData, views of its arrays).

  def state(self, physics, prev_actions):
    """Every Ant's torso frame and proprioception, [n, 5 + PROPRIO_SIZE]:
    x, y, z, cos(yaw), sin(yaw) (`kernels.heading_frames`), then the
    proprioception in `kernels.PROPRIO_LAYOUT` order
    (`kernels.proprio_columns` names it)."""
    data = physics.data.ptr
    if self._bound[0] is not data:  # Views into this mjData, kept with it.
      self._bound = (data, (data.xpos, data.xmat, data.qpos, data.qvel))
    return kernels.agent_state(*self._bound[1], self._torso, self._qpos,
                               self._dof, self._free, prev_actions)


PROPRIOCEPTION_KEYS = tuple(name for name, _ in kernels.PROPRIO_LAYOUT)
