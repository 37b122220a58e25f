"""Co-design schemes (paper Sec. 3.2 and Table 1): how the optics step balances utility and privacy.

Each scheme is a registered lens name and pairs what is trained (optics, adversary) with a
balancing method from `benchmark.codesign.balancing`: fixed lambda_deb (paper eq. 3), MTAdam, the
gradient penalty (eq. 4), or the attack-independent information bound (`os-info`: no min-max, no
RED10). `fixed` trains no optics: it fine-tunes the utility network to a fixed lens.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from benchmark.codesign.balancing import Balance, FixedLambda, GradientPenalty, InformationBound, MTAdamBalance


@dataclass(frozen=True)
class Scheme:
    name: str
    description: str
    optics: bool = True             # step the Zernike coefficients
    adversary: bool = True          # train RED10 and use L_deb
    balance: Balance = field(default_factory=FixedLambda)


SCHEMES: dict[str, Scheme] = {
    s.name: s
    for s in (
        Scheme("os", "optics + segmentation only (no adversary)", adversary=False),
        Scheme("os-d-1", "adversarial, lambda_deb = 1", balance=FixedLambda(lambda_deb=1.0)),
        Scheme("os-d-100", "adversarial, lambda_deb = 100", balance=FixedLambda(lambda_deb=100.0)),
        Scheme("os-d-1000", "adversarial, lambda_deb = 1000", balance=FixedLambda(lambda_deb=1000.0)),
        Scheme("os-d-mtadam", "adversarial, L_seg and -L_deb balanced by MTAdam",
               balance=MTAdamBalance(lambda_deb=1.0)),
        Scheme("gp", "adversarial, lambda_deb = 1 plus the scale-free gradient penalty "
               "(||dL_deb/dtheta_opt|| / ||dL_seg/dtheta_opt|| - 1)^2", balance=GradientPenalty(lambda_deb=1.0)),
        Scheme("gp-literal", "adversarial, lambda_deb = 1 plus the paper's eq. 4 as printed, "
               "(||dL_deb/dtheta_opt||_2 - 1)^2 with theta_opt in um (ablation)",
               balance=GradientPenalty(lambda_deb=1.0, scale_free=False)),
        Scheme("os-info", "optics + segmentation against the information bound at 32 px plates, no adversary",
               adversary=False, balance=InformationBound(lambda_info=0.01, width_px=32, eps=0.05)),
        Scheme("fixed", "no optics step: the utility net fine-tuned to a fixed lens", optics=False, adversary=False),
    )
}
