"""Co-design of the lens with the utility network and the deblurring adversary."""

from lenses.codesign.mtadam import MTAdam

__all__ = ["MTAdam"]
