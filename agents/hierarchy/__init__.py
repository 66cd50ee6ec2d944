"""The hierarchical cooperative agent (paper section 4), Acme-style layout.

The upper layer (UL) turns exteroception into features, the middle layer (ML,
a GRU) turns a sequence of features into commands for the frozen lower layer
(LL, `agents.lowlevel`), which the runner steps k times per command. This
package trains UL + ML with the recurrent PPO learner of `agents.ppo`; the
ablations of the paper are selected by `HierarchyConfig.agent` and read
through its properties (`recurrent`, `uses_commands`, `uses_global_state`).
The variant 'lowlevel' is the lower layer itself, on a locomotion task: its
trained policy is exported as a controller (`coop-pretrain-lowlevel`).

config.py    HierarchyConfig: agent variant and hyper-parameters.
modules.py   Flax modules: upper layer, resetting GRU middle layer, heads,
             the critic (its own layers, stop-gradient or shared).
networks.py  HierarchyNetworks: pure `init` / `unroll` / `step` functions.
learning.py  HierarchyLearner: PPOLearner with the variant's checkpoints.
legacy.py    Reads learner files of the first layout (format 1).
acting.py    HierarchyActor: B agents at once, GRU state carried per row.
builder.py   HierarchyBuilder: config -> networks -> learner / actors.
"""
