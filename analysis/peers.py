"""``python analysis/peers.py``: the peers' tables on pendulum chains (analysis/chains/peers.py), at the README's path."""
import hnn

hnn.tasks.import_analysis()   # hnn_analysis = this folder, installed or run by path from a checkout
from hnn_analysis.chains.peers import main  # noqa: E402

if __name__ == "__main__":
    main()
