"""The paper's findings (and a few checks of the suite's own), decided on the leaderboard's entries
by paired comparisons on the same scenes and plates (computed, never typed in).

Two lenses of one profile are compared only where both entries carry per-unit outcomes
(``schema.Units``) for the same seeds: units are paired by id within each seed (scene names and
plate ids depend on scene set, split, seed and index only, not on the lens), and the seeds are
pooled by resampling within each seed (stratified). The measures:

- ``miou``: the utility row's mIoU, recomputed from per-scene, per-class intersection and union
  counts in every resample (mean over seeds of each seed's pooled mIoU); paired bootstrap.
- ``psnr_db``: the ensemble's PSNR (benchmark.results.ensemble): each scene at its best restorer
  among the restorers both lenses met, averaged over scenes (the per-scene maximum is taken inside
  each resample); paired bootstrap.
- ``plate_acc``: the ensemble's plate accuracy: a plate counts as read when any reader chain both
  lenses met read it exactly; McNemar's exact test on the ensemble's per-plate reads, paired by
  plate id and pooled over seeds, with Newcombe's interval of the paired difference.

Both ensembles are the per-unit worst case over every attacker both entries ran with per-unit
outcomes at every shared seed (an attacker missing a seed on either side is left out rather than
unpaired), so a claim on privacy is decided by the strongest attack the suite has, not by one reader.

Each finding says "holds", "does not hold" or "cannot tell at this sample size" with the
difference, its 95 % interval, the p-value and n (``benchmark.results.stats.verdict``); a claim that "a is
no higher than b" holds only when a is significantly lower (equal within the interval: cannot
tell). Entries without per-unit outcomes (published before they existed) get "cannot tell: entry
has no per-unit outcomes (re-publish)": no pairing is ever guessed. Nor are entries whose nets (or,
for two co-designed lenses, whose optics) were made by different co-design trainer versions (rows'
note ``trainer_version``; "not noted" counts as a version of its own): "cannot tell: ... re-publish".
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from benchmark.results import stats
from benchmark.results.ensemble import plate_ensemble, scene_ensemble, seed_plates
from benchmark.results.entries import ATTACKER_KINDS, Entry, Stat
from benchmark.results.schema import Units

N_RESAMPLES = 4000
NO_UNITS = "cannot tell: entry has no per-unit outcomes (re-publish)"


@dataclasses.dataclass(frozen=True)
class Claim:
    """A finding: "``a`` is ``direction`` than ``b`` on ``measure``" (see the module docstring)."""

    text: str
    a: str
    b: str
    measure: str        # "miou", "psnr_db" or "plate_acc"
    direction: stats.Direction
    source: str = "paper"   # "paper", or "suite" for a check of the suite's own baselines


PAPER_FINDINGS = (
    Claim("more lambda_deb costs utility", "os-d-1", "os-d-1000", "miou", "greater"),
    Claim("more lambda_deb lowers the attackers' PSNR (each scene at its best restorer)", "os-d-1", "os-d-1000", "psnr_db", "greater"),
    Claim("more lambda_deb costs utility (1 against 100)", "os-d-1", "os-d-100", "miou", "greater"),
    Claim("more lambda_deb costs utility (100 against 1000)", "os-d-100", "os-d-1000", "miou", "greater"),
    Claim("GP gives lambda_deb = 1000 privacy (attacker PSNR no higher)", "gp", "os-d-1000", "psnr_db", "less"),
    Claim("GP gives lambda_deb = 1000 plate privacy (the ensemble of readers reads no more)", "gp", "os-d-1000", "plate_acc", "less"),
    Claim("GP keeps more utility than lambda_deb = 1000", "gp", "os-d-1000", "miou", "greater"),
    Claim("MTAdam gives weaker privacy than lambda_deb = 1000", "os-d-mtadam", "os-d-1000", "psnr_db", "greater"),
    Claim("GP costs utility against no adversary (OS)", "gp", "os", "miou", "less"),
    Claim("GP lowers the attacker's PSNR against OS", "gp", "os", "psnr_db", "less"),
    Claim("GP lowers the readers' ensemble plate accuracy against OS", "gp", "os", "plate_acc", "less"),
    Claim("the scale-free GP gives more privacy than eq. 4 taken literally (attacker PSNR lower)", "gp",
          "gp-literal", "psnr_db", "less", "suite"),
    Claim("the scale-free GP keeps the utility of eq. 4 taken literally", "gp", "gp-literal", "miou", "greater",
          "suite"),
    Claim("the scale-free GP lowers the readers' ensemble plate accuracy against eq. 4 taken literally", "gp",
          "gp-literal", "plate_acc", "less", "suite"),
    Claim("an information-bound adversary (os-info) lowers the attacker's PSNR against OS", "os-info", "os",
          "psnr_db", "less", "suite"),
    Claim("an information-bound adversary (os-info) costs utility against OS", "os-info", "os", "miou", "less",
          "suite"),
    Claim("defocus costs utility against the ideal lens", "defocus", "ideal", "miou", "less", "suite"),
    Claim("defocus lowers the attacker's PSNR against the ideal lens", "defocus", "ideal", "psnr_db", "less", "suite"),
    Claim("defocus lowers the readers' ensemble plate accuracy against the ideal lens", "defocus", "ideal", "plate_acc",
          "less", "suite"),
)


# How each measure's figures and differences are printed: (digits, scale, unit).
FORMATS = {"miou": (3, 1.0, ""), "psnr_db": (2, 1.0, " dB"), "plate_acc": (1, 100.0, " pt")}


@dataclasses.dataclass(frozen=True)
class Finding:
    """One claim checked on one profile.

    Attributes:
        a, b: Each lens's figure as the leaderboard shows it (mean ± seed std), or None.
        attack_a, attack_b: The chain behind each figure ("utility", the strongest restorer or reader).
        comparison: The paired comparison of a - b (None when it could not be made).
        label: stats.HOLDS / DOES_NOT_HOLD / CANNOT_TELL.
        verdict: The label with its evidence, or why no paired comparison was possible.
    """

    profile: str
    claim: str
    lens_a: str
    lens_b: str
    measure: str
    source: str
    a: Stat | None
    b: Stat | None
    attack_a: str | None
    attack_b: str | None
    comparison: stats.Comparison | None
    label: str
    verdict: str

    @property
    def difference(self) -> float | None:
        """a - b of the paired comparison (None where none was made)."""
        return None if self.comparison is None else self.comparison.difference

    def figure_text(self, side: str) -> str:
        """"mean ± seed std (attack)" of side "a" or "b", in the measure's units ("" for none)."""
        stat, attack = (self.a, self.attack_a) if side == "a" else (self.b, self.attack_b)
        if stat is None:
            return ""
        digits, scale, _ = FORMATS[self.measure]
        text = f"{stat.mean * scale:.{digits}f}" + (f" ± {stat.std * scale:.{digits}f}" if stat.std else "")
        return text + (f" ({attack})" if attack and attack != "utility" else "")

    def difference_text(self) -> str:
        """"a - b [low, high]" of the paired comparison, in the measure's units ("" where none was made)."""
        c = self.comparison
        if c is None:
            return ""
        digits, scale, unit = FORMATS[self.measure]
        return f"{c.difference * scale:+.{digits}f} [{c.low * scale:+.{digits}f}, {c.high * scale:+.{digits}f}]{unit}"

    def p_text(self) -> str:
        c = self.comparison
        return "" if c is None else ("< 0.001" if c.p_value < 0.001 else f"{c.p_value:.3f}")

    def decision_text(self) -> str:
        """The label where a paired comparison decided it, else why none could be made."""
        return self.label if self.comparison is not None else self.verdict


class _Unpaired(Exception):
    """Why two entries cannot be compared unit by unit (the message is the verdict)."""


def _aligned(pairs: Sequence[Units]) -> list[list[int]]:
    """For units of one seed (several rows, all sides), the indices of the ids they all hold, in one order."""
    names = [u.names() for u in pairs]
    common = set(names[0]).intersection(*names[1:])
    if not common:
        raise _Unpaired("cannot tell: the two entries share no scene or plate id for this seed (different scenes)")
    order = [n for n in names[0] if n in common]
    positions = [{name: i for i, name in enumerate(n)} for n in names]
    return [[where[k] for k in order] for where in positions]


def _miou(strata: Sequence[np.ndarray]) -> float:
    """Mean over strata of the pooled mIoU; each stratum (n, 2, C): per scene intersection and union."""
    values = []
    for x in strata:
        inter, union = x[:, 0].sum(axis=0), x[:, 1].sum(axis=0)
        present = union > 0
        values.append(float((inter[present] / union[present]).mean()) if present.any() else np.nan)
    return float(np.mean(values))


def _best_per_scene(strata: Sequence[np.ndarray]) -> float:
    """Mean over strata of the mean over scenes of each scene's best column (restorer); strata (n, R)."""
    return float(np.mean([x.max(axis=1).mean() for x in strata]))


def _compare_miou(ea: Entry, eb: Entry) -> tuple[stats.Comparison, Figure, Figure]:
    _, seeds = _with_units(ea, eb, ["utility"], "intersection")
    sa, sb = [], []
    for s in seeds:
        ua, ub = ea.units("utility", s), eb.units("utility", s)
        assert ua is not None and ub is not None
        ia, ib = _aligned([ua, ub])
        sa.append(np.stack([np.array(ua.values["intersection"])[ia], np.array(ua.values["union"])[ia]], axis=1))
        sb.append(np.stack([np.array(ub.values["intersection"])[ib], np.array(ub.values["union"])[ib]], axis=1))
    return (stats.stratified_paired_bootstrap(sa, sb, _miou, n_resamples=N_RESAMPLES),
            (ea.metric("utility", "miou"), "utility"), (eb.metric("utility", "miou"), "utility"))


def _common_attacks(ea: Entry, eb: Entry, kind: str, metric: str) -> list[str]:
    kinds = ATTACKER_KINDS[kind]
    have = lambda e: [c.attack for c in e.chains() if c.kind in kinds and metric in c.metrics]  # noqa: E731
    common = [a for a in have(ea) if a in set(have(eb))]
    if not common:
        raise _Unpaired(f"cannot tell: no attacker with {metric} ran on both lenses")
    return common


def _with_units(ea: Entry, eb: Entry, attacks: Sequence[str], value: str) -> tuple[list[str], list[int]]:
    """Those of `attacks` whose rows carry units holding `value` on both entries for every seed the
    entries share, and those seeds (an attacker missing a seed is left out rather than unpaired)."""
    seeds = sorted(set(ea.seeds) & set(eb.seeds))
    if not seeds:
        raise _Unpaired("cannot tell: the entries share no seed")
    usable = [a for a in attacks
              if all((u := e.units(a, s)) is not None and value in u.values for e in (ea, eb) for s in seeds)]
    if not usable:
        raise _Unpaired(NO_UNITS)
    return usable, seeds


Figure = tuple[Stat | None, str | None]


def _seed_rows(entry: Entry, seeds: Sequence[int]) -> list:
    return [r for r in entry.rows if r.seed in set(seeds)]


def _compare_psnr(ea: Entry, eb: Entry) -> tuple[stats.Comparison, Figure, Figure]:
    attacks, seeds = _with_units(ea, eb, _common_attacks(ea, eb, "restorer", "psnr_db"), "psnr_db")
    sa, sb = [], []
    for s in seeds:
        units = [e.units(a, s) for e in (ea, eb) for a in attacks]
        index = _aligned(units)  # type: ignore[arg-type]
        columns = [np.array(u.values["psnr_db"])[i] for u, i in zip(units, index)]  # type: ignore[union-attr]
        sa.append(np.stack(columns[:len(attacks)], axis=1))
        sb.append(np.stack(columns[len(attacks):], axis=1))
    comparison = stats.stratified_paired_bootstrap(sa, sb, _best_per_scene, n_resamples=N_RESAMPLES)
    label = f"per-scene best of {len(attacks)} restorers"

    def figure(e: Entry) -> Figure:
        found = scene_ensemble(_seed_rows(e, seeds), "psnr_db", set(attacks))
        if found is None:
            return None, label
        return Stat(found.mean, found.seed_std, found.seed_values, found.interval), label
    return comparison, figure(ea), figure(eb)


def _compare_plates(ea: Entry, eb: Entry) -> tuple[stats.Comparison, Figure, Figure]:
    attacks, seeds = _with_units(ea, eb, _common_attacks(ea, eb, "reader", "plate_acc"), "correct")
    chosen = set(attacks)
    cells = np.zeros(4, dtype=int)  # both, only a, only b, neither
    for s in seeds:
        pa, pb = seed_plates(ea.rows, s, chosen), seed_plates(eb.rows, s, chosen)
        if pa is None or pb is None or not pa.names or not pb.names:
            continue
        common = set(pa.names) & set(pb.names)
        if not common:
            raise _Unpaired("cannot tell: the two entries share no plate id for this seed (different scenes)")
        where_b = {n: i for i, n in enumerate(pb.names)}
        order = [i for i, n in enumerate(pa.names) if n in common]
        ra = pa.ensemble[order]
        rb = pb.ensemble[[where_b[pa.names[i]] for i in order]]
        cells += stats.paired_table(ra, rb)
    if cells.sum() == 0:
        raise _Unpaired("cannot tell: no readable plate was scored on both lenses")
    label = f"ensemble of {len(attacks)} chains"

    def figure(e: Entry) -> Figure:
        found = plate_ensemble(_seed_rows(e, seeds), chosen)
        if found is None:
            return None, label
        a = found.accuracy
        values = tuple(a.seed_values)
        return Stat(a.value, a.seed_std, values, a.interval), label
    return stats.paired_accuracy_difference(*(int(c) for c in cells)), figure(ea), figure(eb)


_COMPARE = {"miou": _compare_miou, "psnr_db": _compare_psnr, "plate_acc": _compare_plates}
_FIGURE_KIND = {"psnr_db": "restorer", "plate_acc": "reader"}


def _figure(entry: Entry, measure: str) -> Stat | None:
    """The entry's own figure where no paired comparison was made: utility, or the strongest single
    attacker's (whether the measure applies at all)."""
    if measure == "miou":
        return entry.metric("utility", "miou")
    found = entry.worst_case(measure, _FIGURE_KIND[measure])
    return None if found is None else found[0]


def co_designed(lens: str) -> bool:
    """Whether each seed of `lens` trains its own coefficients (a co-design scheme)."""
    from benchmark.codesign.schemes import SCHEMES  # the schemes pull in torch: only when asked
    return lens in SCHEMES


def _version_text(versions: set[str | None]) -> str:
    return "/".join(sorted(v or "not noted" for v in versions))


def _same_trainer(claim: Claim, ea: Entry, eb: Entry) -> None:
    """Raise _Unpaired when the two sides were made by different co-design trainer versions: the
    utility nets for mIoU (every lens's net is fine-tuned by the trainer), the optics for privacy
    when both lenses are co-designed (a fixed lens's optics do not depend on the trainer)."""
    if claim.measure == "miou":
        kinds: tuple[str, ...] = ("utility",)
    elif co_designed(ea.lens) and co_designed(eb.lens):
        kinds = ("lens",)
    else:
        return
    va, vb = ea.trainer_versions(kinds), eb.trainer_versions(kinds)
    if va and vb and va != vb:
        raise _Unpaired(f"cannot tell: {ea.lens} and {eb.lens} were trained by different co-design trainer "
                        f"versions ({_version_text(va)} against {_version_text(vb)}; re-publish with the current one)")


def check_claim(claim: Claim, ea: Entry, eb: Entry) -> Finding:
    """Decide `claim` on the entries of its two lenses (one profile) by a paired comparison; entries
    made by different co-design trainer versions are not compared (``_same_trainer``)."""
    try:
        _same_trainer(claim, ea, eb)
        comparison, (stat_a, attack_a), (stat_b, attack_b) = _COMPARE[claim.measure](ea, eb)
    except _Unpaired as why:
        return Finding(ea.profile, claim.text, claim.a, claim.b, claim.measure, claim.source,
                       _figure(ea, claim.measure), _figure(eb, claim.measure), None, None, None,
                       stats.CANNOT_TELL, str(why))
    decided = stats.verdict(comparison, claim.direction)
    return Finding(ea.profile, claim.text, claim.a, claim.b, claim.measure, claim.source,
                   stat_a, stat_b, attack_a, attack_b, comparison, decided.label, decided.text)


def check_findings(entries: Sequence[Entry], claims: Sequence[Claim] = PAPER_FINDINGS) -> list[Finding]:
    """Every claim whose two lenses have entries of the same profile and scenes, both with the claim's
    measure, decided on them."""
    found = []
    by_key = {(e.lens, e.profile, e.scenes): e for e in entries}
    for profile, scenes in dict.fromkeys((e.profile, e.scenes) for e in entries):
        for claim in claims:
            ea, eb = by_key.get((claim.a, profile, scenes)), by_key.get((claim.b, profile, scenes))
            if ea is None or eb is None:
                continue
            if _figure(ea, claim.measure) is None or _figure(eb, claim.measure) is None:
                continue  # nothing measured on one side: the claim does not apply
            found.append(check_claim(claim, ea, eb))
    return found
