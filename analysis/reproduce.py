"""``python analysis/reproduce.py``: the paper's reproduction (analysis/paper/reproduce.py), at the README's path."""
from hnn_analysis.paper.reproduce import main

if __name__ == "__main__":
    main()
