"""Co-design of the lens with the utility network and the deblurring adversary (an application of
the physics in `lenses`, the scenes and utility nets of `benchmark`, and RED10 from `attacks`)."""

from benchmark.codesign.mtadam import MTAdam

__all__ = ["MTAdam"]
