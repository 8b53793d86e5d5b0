"""The scene study: which model kind each scene needs (``scene_study``, the command; ``scene_stages``, what
it trains, measures and picks), its measurements (``scene_metrics``) and its report (``scene_report``;
its tables ``scene_tables`` and figure ``scene_figure``)."""
