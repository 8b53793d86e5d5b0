"""The pendulum chain as the package sees it (hnn.TaskSpec): not one of the paper's six tasks.

Its protocols are the peers' (experiment-chain/protocols.py, docs/peers.md), measured by
analysis/peers.py, not the paper's energy MSE; reproduce.py leaves it out.
"""
import hnn

TASK = hnn.TaskSpec(
    order=100,
    in_paper=False,
    cost=60,    # rough: 8000 steps of a 256-unit model through 4-step RK4 snippets, seconds on one core
    data_cost=2.5,    # seconds of one build of a peers.py --quick dataset (5000 states of a 1-bob chain: 2.2 s at load 2)
)
