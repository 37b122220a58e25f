"""The paper's qualitative findings, checked on the leaderboard's entries (computed, never typed in)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from benchmark.leaderboard_entries import Entry, Stat

# (claim, lens a, lens b, metric, kind, expected sign of a - b). kind "utility" reads the utility
# row, "restorer" the strongest restorer's figure; sign 0 means "a no higher than b".
PAPER_FINDINGS = (
    ("more lambda_deb costs utility", "os-d-1", "os-d-1000", "miou", "utility", +1),
    ("more lambda_deb lowers the attacker's PSNR", "os-d-1", "os-d-1000", "psnr_db", "restorer", +1),
    ("GP gives lambda_deb = 1000 privacy (attacker PSNR no higher)", "gp", "os-d-1000", "psnr_db", "restorer", 0),
    ("GP keeps more utility than lambda_deb = 1000", "gp", "os-d-1000", "miou", "utility", +1),
    ("MTAdam gives weaker privacy than lambda_deb = 1000", "os-d-mtadam", "os-d-1000", "psnr_db", "restorer", +1),
)


@dataclasses.dataclass(frozen=True)
class Finding:
    """One claim checked on one profile: both lenses' figures (mean, seed std), a - b and the verdict."""

    profile: str
    claim: str
    lens_a: str
    lens_b: str
    a: Stat
    b: Stat
    verdict: str

    @property
    def difference(self) -> float:
        return self.a.mean - self.b.mean


def _value(entry: Entry, name: str, kind: str, attacks: set[str]) -> Stat | None:
    """The utility metric, or the strongest attacker's figure among ``attacks`` (those both lenses met)."""
    if kind == "utility":
        return entry.metric("utility", name)
    found = entry.worst_case(name, kind, attacks)
    return None if found is None else found[0]


def verdict(a: Stat, b: Stat, sign: int, one_seed: bool) -> str:
    """"holds" / "does not hold" / "within seed noise", from a - b against the two seed spreads added.

    A difference no larger than the spreads is within noise; a sign-0 claim ("a no higher than b")
    holds when a - b <= the spreads. With a single seed on either side there is no spread: the
    verdict says so.
    """
    diff, noise = a.mean - b.mean, a.std + b.std
    if sign == 0:
        text = "holds" if diff <= noise else "does not hold"
    elif abs(diff) <= noise:
        text = "within seed noise"
    else:
        text = "holds" if diff * sign > 0 else "does not hold"
    if one_seed and text != "within seed noise":
        text += " (one seed: no spread)"
    return text


def check_findings(entries: Sequence[Entry]) -> list[Finding]:
    """Every paper claim whose two lenses have entries of the same profile, checked on them.

    Attacker figures are the strongest attacker among those that ran on both lenses, so that a
    richer attacker set on one side does not decide the comparison.
    """
    found = []
    by_key = {(e.lens, e.profile): e for e in entries}
    for profile in dict.fromkeys(e.profile for e in entries):
        for claim, a, b, name, kind, sign in PAPER_FINDINGS:
            if (a, profile) not in by_key or (b, profile) not in by_key:
                continue
            ea, eb = by_key[a, profile], by_key[b, profile]
            common = {c.attack for c in ea.chains()} & {c.attack for c in eb.chains()}
            va, vb = _value(ea, name, kind, common), _value(eb, name, kind, common)
            if va is None or vb is None:
                continue
            found.append(Finding(profile, claim, a, b, va, vb,
                                 verdict(va, vb, sign, len(ea.seeds) < 2 or len(eb.seeds) < 2)))
    return found
