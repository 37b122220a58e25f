"""Studies: one-off measurements that back a modelling choice or a ceiling, published beside the
leaderboard: the PSF grid (``psf_grid``), the utility net's size (``utility_size``), NAFNet's steps
(``nafnet_steps_study``), the co-design's speed (``codesign_speed``), the ideal observer's ceiling
(``observer_study``) and the reader study against it (``reader_study``), where readable plates start
(``readable_start_study``) and the standard ensemble (``ensemble_choice_study``, which writes
docs/ensemble.md).

Each study writes one JSON file under ``leaderboard/studies/`` (``python -m benchmark study NAME``);
``python -m benchmark report`` renders its chart from that file alone.
"""
