"""The least-squares fits measured (hnn.fits): the Sampling-HNNs protocols (``sampling_hnns``) and the fits on
the paper's tasks and the chains beside Adam and SINDy (``fit_tasks``)."""
