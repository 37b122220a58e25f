"""Co-design schemes (paper Sec. 3.2 and Table 1): how the optics step balances utility and privacy.

Each scheme is a registered lens name. The optics minimise lambda_seg L_seg - lambda_deb L_deb,
optionally + (||dL_deb / dtheta_opt||_2 - 1)^2 (gradient penalty, eq. 4), or balance the two terms
with MTAdam. `fixed` trains no optics: it fine-tunes the utility network to a fixed lens.
`os-info` replaces the adversary by the attack-independent bound (lenses/bound.py): the optics
minimise lambda_seg L_seg + lambda_info relu((B(w_target) + 1) / H_plate - eps), with B the bits a
plate w_target px wide leaks and (B + 1) / H_plate its Fano ceiling, left unclipped so that its
gradient never vanishes; no min-max, no RED10.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Scheme:
    name: str
    description: str
    optics: bool = True             # step the Zernike coefficients
    adversary: bool = True          # train RED10 and use L_deb
    lambda_deb: float = 0.0
    balance: str = "fixed"          # "fixed" | "mtadam" | "gp" | "info"
    lambda_seg: float = 1.0
    lambda_info: float = 0.0        # weight of the bound term (os-info)
    info_width_px: int = 32         # plate width the bound term protects: the median plate of the scenes
    info_eps: float = 0.05          # target ceiling on any attacker's exact-read rate


SCHEMES: dict[str, Scheme] = {
    s.name: s
    for s in (
        Scheme("os", "optics + segmentation only (no adversary)", adversary=False),
        Scheme("os-d-1", "adversarial, lambda_deb = 1", lambda_deb=1.0),
        Scheme("os-d-100", "adversarial, lambda_deb = 100", lambda_deb=100.0),
        Scheme("os-d-1000", "adversarial, lambda_deb = 1000", lambda_deb=1000.0),
        Scheme("os-d-mtadam", "adversarial, L_seg and -L_deb balanced by MTAdam", lambda_deb=1.0, balance="mtadam"),
        Scheme("gp", "adversarial, lambda_deb = 1 plus the gradient penalty (||dL_deb/dtheta_opt|| - 1)^2",
               lambda_deb=1.0, balance="gp"),
        Scheme("os-info", "optics + segmentation against the information bound at 32 px plates, no adversary",
               adversary=False, balance="info", lambda_info=0.01),
        Scheme("fixed", "no optics step: the utility net fine-tuned to a fixed lens", optics=False, adversary=False),
    )
}
