"""``python analysis/scene_study.py``: the scene study (analysis/scenes/scene_study.py), at the README's path."""
from hnn_analysis.scenes.scene_study import main

if __name__ == "__main__":
    main()
