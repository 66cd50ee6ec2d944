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
