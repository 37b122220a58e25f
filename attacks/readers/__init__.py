"""Readers: one attacker per file, each pulling plate strings out of images (``attacks.base.Reader``):
the paper's detector pipeline (``lpdr``, its stages in ``plates/``), the learned reader and the
analysis-by-synthesis ``ideal-observer`` reader."""
