"""Utility-task models: what the privacy-preserving camera must stay useful for."""

from benchmark.codesign.utility.segformer import build_segformer, load_segformer_weights, segment_logits, sliding_window_logits

__all__ = ["build_segformer", "load_segformer_weights", "segment_logits", "sliding_window_logits"]
