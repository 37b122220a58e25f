"""Neural networks used by the attackers: NAFNet (restorer, ``nafnet``) and its folded inference form
(``nafnet_folded``), RED10 (co-design adversary, ``red10``) and the learned reader's plate CNN
(``plate_cnn``)."""

from attacks.networks.nafnet import NAFNet, load_nafnet_checkpoint
from attacks.networks.red10 import RED10

__all__ = ["NAFNet", "RED10", "load_nafnet_checkpoint"]
