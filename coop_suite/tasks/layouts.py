"""Starting layouts that adapt to any population, and pose placement.

An upright Ant covers a disc of about 0.7 m radius, so layouts keep centres at
least `ANT_SPACING` apart; rings and arcs grow with the agent count instead of
letting ants overlap (overlaps would explode the first physics step).
"""

import numpy as np

from coop_suite.entities import STANDING_HEIGHT

ANT_SPACING = 1.7  # metres between neighbouring ant centres.


def ring(n, center, min_radius, random_state, jitter=0.2, offset=np.pi / 4):
  """`n` points evenly spread on a circle around `center`.

  With 4 agents and the default `offset` there is one per quadrant. The
  radius grows so that neighbours stay `ANT_SPACING` apart; each point gets
  up to `jitter` metres of random radial noise and a small angular noise.
  Returns: [n, 2] world xy (metres).
  """
  radius = max(min_radius, n * ANT_SPACING / (2 * np.pi))
  step = 2 * np.pi / n
  angles = offset + step * np.arange(n)
  angles += random_state.uniform(-0.15, 0.15, n) * min(step, 1.0)
  radii = radius + random_state.uniform(0, jitter, n)
  return np.asarray(center) + np.stack(
      [radii * np.cos(angles), radii * np.sin(angles)], -1)


def annulus(n, center, radii, random_state, spacing=ANT_SPACING,
            attempts=1000):
  """`n` points drawn uniformly (by area) over the annulus `radii` = (inner,
  outer) around `center`, at least `spacing` apart.

  No pattern is imposed: several agents may start on one side, some near and
  some far. Each point is redrawn until it clears the ones before it; the
  outer radius grows by 10% whenever `attempts` draws in a row fail (a dense
  population still fits). Returns: [n, 2] world xy (metres).
  """
  inner, outer = float(radii[0]), float(radii[1])
  if not 0 <= inner <= outer:
    raise ValueError(f"radii must be 0 <= inner <= outer, got {radii}.")
  points = []
  while len(points) < n:
    for _ in range(attempts):
      radius = np.sqrt(random_state.uniform(inner ** 2, outer ** 2))
      angle = random_state.uniform(-np.pi, np.pi)
      point = radius * np.array([np.cos(angle), np.sin(angle)])
      if all(np.linalg.norm(point - q) >= spacing for q in points):
        points.append(point)
        break
    else:
      outer *= 1.1
  return np.asarray(center) + np.array(points).reshape(n, 2)


def arc(n, center, min_radius, facing, max_spread=0.8 * np.pi):
  """`n` points on an arc at one distance from `center`, opening away from it.

  Every point is equally far from `center` (the corridor's slit), spread
  over at most `max_spread` radians around the direction `facing` (radians,
  pointing from the centre towards the agents); the radius grows with `n`.
  Returns: [n, 2] world xy (metres).
  """
  if n == 1:
    angles = np.array([facing])
    radius = min_radius
  else:
    radius = max(min_radius, (n - 1) * ANT_SPACING / max_spread)
    spread = (n - 1) * ANT_SPACING / radius
    angles = facing + np.linspace(-spread / 2, spread / 2, n)
  return np.asarray(center) + radius * np.stack(
      [np.cos(angles), np.sin(angles)], -1)


def line(n, x, center_y, spacing=ANT_SPACING):
  """`n` points on the line x = `x`, `spacing` apart, centred on `center_y`."""
  ys = center_y + (np.arange(n) - (n - 1) / 2) * spacing
  return np.stack([np.full(n, x), ys], -1)


def place(walker, physics, xy, yaw, random_state, ground_z=0.0,
          joint_noise=0.1):
  """Puts `walker` upright at world `xy` facing `yaw`, at rest.

  Joint angles get uniform noise of +-`joint_noise` radians so episodes do
  not start from a single symmetric pose.
  """
  position = np.array([xy[0], xy[1], ground_z + STANDING_HEIGHT])
  quaternion = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
  walker.set_pose(physics, position=position, quaternion=quaternion)
  walker.set_velocity(physics, velocity=np.zeros(3),
                      angular_velocity=np.zeros(3))
  joints = physics.bind(walker.joints)
  joints.qpos = random_state.uniform(-joint_noise, joint_noise, len(joints.qpos))
  joints.qvel = 0.0


def place_prop(prop, physics, xyz, yaw=0.0):
  """Puts a free prop at world `xyz` with heading `yaw`, at rest."""
  quaternion = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
  prop.set_pose(physics, position=np.asarray(xyz, dtype=np.float64),
                quaternion=quaternion)
  prop.set_velocity(physics, velocity=np.zeros(3), angular_velocity=np.zeros(3))


def face(points, target):
  """Yaw (radians) from each of `points` [n, 2] towards `target` [2]."""
  delta = np.asarray(target) - np.asarray(points)
  return np.arctan2(delta[:, 1], delta[:, 0])
