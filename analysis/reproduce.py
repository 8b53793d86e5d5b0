"""``python analysis/reproduce.py``: the paper's reproduction (analysis/paper/reproduce.py), at the README's path."""
import hnn

hnn.tasks.import_analysis()   # hnn_analysis = this folder, installed or run by path from a checkout
from hnn_analysis.paper.reproduce import main  # noqa: E402

if __name__ == "__main__":
    main()
