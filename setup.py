"""coop-suite: embodied multi-agent cooperation with MuJoCo Ants.

One package set: the dm_control task suite (`coop_suite`), the Acme-style JAX
agents (`agents`) and the Ray runners (`runners`).
"""
import setuptools

setuptools.setup(
    name="coop-suite",
    version="0.1.0",
    description=(
        "dm_control composer tasks and a distributed hierarchical controller "
        "for embodied multi-agent cooperation with MuJoCo Ants."),
    long_description=open("README.md").read(),
    long_description_content_type="text/markdown",
    packages=setuptools.find_packages(include=["coop_suite*", "agents*", "runners*"]),
    package_data={
        "coop_suite": ["entities/assets/*.xml"],
        "agents": ["lowlevel/weights/*/*"],
    },
    python_requires=">=3.10",
    install_requires=[
        # dm-control 1.0.50 is built against mujoco 3.x; mujoco 4.0 fails at
        # load with "'MjModel' object has no attribute 'flex_vertedge'".
        "dm-control==1.0.50",
        "mujoco>=3.17,<3.18",
        # Compiled per-step features (coop_suite/kernels.py); 0.60 is the
        # first release for numpy 2.
        "numba>=0.60",
        "dm-env",
        "numpy",
        "jax",
        "flax",
        "optax",
        # Checkpoints (runners/checkpoints.py): CheckpointManager with
        # preservation policies (LatestN + BestN); 0.12.8 is the one tested,
        # and orbax's API moves between minor versions.
        "orbax-checkpoint>=0.12.8,<0.13",
        "ray[default]>=2.9",
        "imageio",
        "imageio-ffmpeg",
        "tqdm",
        "matplotlib>=3.6",  # Figure.get_layout_engine (runners.plot).
        "tensorboardX",
        # Every CLI (runners.cli); its private parse-error hook turns a
        # refused value into one line, else tyro's own box: pinned to the
        # minor version tested.
        "tyro>=1.0.17,<1.1",
    ],
    extras_require={
        "pettingzoo": ["pettingzoo>=1.24", "gymnasium>=0.29"],
        # coop_suite.rllib; not in "test": RLlib pins gymnasium and pulls
        # pandas and pyarrow (tests/test_rllib.py skips without it).
        "rllib": ["ray[rllib]>=2.9", "pettingzoo>=1.24"],
        # The TensorBoard viewer for a run's events (tensorboardX writes
        # them and is installed anyway).
        "tensorboard": ["tensorboard"],
        # benchmarks/profile_training.py samples a running training's actor.
        "profile": ["py-spy"],
        # pytest-xdist: README's test command runs the suite on 2 processes.
        "test": ["pytest", "pytest-xdist>=3.5", "pettingzoo>=1.24",
                 "gymnasium>=0.29"],
    },
    entry_points={
        "console_scripts": [
            "coop-video=runners.video:main",
            "coop-pretrain-lowlevel=runners.pretrain_lowlevel:main",
            "coop-train=runners.train:main",
            "coop-eval=runners.evaluate:main",
            "coop-paper=runners.paper:main",
            "coop-compare=runners.compare:main",
        ],
    },
)
