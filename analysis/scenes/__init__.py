"""The scene study: which model kind each scene needs (``scene_study``, the command; ``scene_stages``, what
it trains, measures and picks), its measurements (``scene_metrics``) and its report (``scene_report``;
its tables ``scene_tables`` and figure ``scene_figure``); and the bodies study's machinery (``bodies_study``:
the pair kind fitted on a few bodies and rolled out on many; ``analysis/bodies.py`` is its command)."""
