"""Modelling-choice studies: measurements showing that each model is no larger than a scene needs.

Each study writes one JSON file under ``leaderboard/studies/`` (``python -m benchmark study NAME``);
``python -m benchmark report`` renders its chart from that file alone.
"""
