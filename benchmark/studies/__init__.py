"""Studies: one-off measurements that back a modelling choice or a ceiling, published beside the
leaderboard (the PSF grid, the utility net's size, NAFNet's steps, the co-design's speed, the ideal
observer's ceiling and the reader study against it).

Each study writes one JSON file under ``leaderboard/studies/`` (``python -m benchmark study NAME``);
``python -m benchmark report`` renders its chart from that file alone.
"""
