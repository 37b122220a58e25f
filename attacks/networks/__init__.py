"""Neural networks used by the attackers: NAFNet (restorer) and RED10 (co-design adversary)."""

from attacks.networks.nafnet import NAFNet, load_nafnet_checkpoint
from attacks.networks.red10 import RED10

__all__ = ["NAFNet", "RED10", "load_nafnet_checkpoint"]
