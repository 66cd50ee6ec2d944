"""The newcomer's rough edges: what the CLIs tell a first-time user."""
from runners import video


def test_ravine_video_names_crossers_and_pushers(tmp_path, capsys):
  video.main(["--task", "ravine", "--n-agents", "2", "--png",
              str(tmp_path / "still.png"), "--width", "32", "--height", "24"])
  assert "ravine with 2 crossers and 2 pushers" in capsys.readouterr().out


def test_population_of_single_species_tasks_is_agents():
  assert video.population(("ant",) * 4) == "4 agents"
  assert video.population(("ant",)) == "1 agent"
  assert video.population(("crosser", "pusher")) == "1 crosser and 1 pusher"


def test_video_writer_runs_no_fork_handlers_beside_jax(tmp_path):
  # coop-eval --video films with JAX's threads running; a `preexec_fn`
  # makes Python run fork handlers, and JAX's warns of a deadlock.
  import warnings  # pylint: disable=g-import-not-at-top
  import jax.numpy as jnp  # pylint: disable=g-import-not-at-top
  import numpy as np  # pylint: disable=g-import-not-at-top
  jnp.ones(3).block_until_ready()
  with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    writer = video.open_video(str(tmp_path / "clip.mp4"), fps=20)
    writer.append_data(np.zeros((16, 16, 3), np.uint8))
    writer.close()
  assert not [w for w in caught if "fork" in str(w.message)]
  assert (tmp_path / "clip.mp4").stat().st_size > 0
