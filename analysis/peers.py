"""``python analysis/peers.py``: the peers' tables on pendulum chains (analysis/chains/peers.py), at the README's path."""
from hnn_analysis.chains.peers import main

if __name__ == "__main__":
    main()
