"""The scene study: which model kind each scene needs (``scene_study``), its measurements
(``scene_metrics``) and its report (``scene_report``)."""
