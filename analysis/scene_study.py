"""``python analysis/scene_study.py``: the scene study (analysis/scenes/scene_study.py), at the README's path."""
import hnn

hnn.tasks.import_analysis()   # hnn_analysis = this folder, installed or run by path from a checkout
from hnn_analysis.scenes.scene_study import main  # noqa: E402

if __name__ == "__main__":
    main()
