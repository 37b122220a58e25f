"""The leaderboard's tables, from its entries: the trade-off table, the findings and every attacker.

The trade-off table's columns are defined once (``MAIN_COLUMNS``): the markdown table and the web
page's sortable table are both rendered from them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

from benchmark.findings import check_findings
from benchmark.leaderboard_entries import Entry, Stat

# A cell: its text and the number it sorts by (None: empty).
Cell = tuple[str, float | None]


def pm(stat: Stat | None, digits: int = 3, pct: bool = False) -> str:
    """"mean ± seed std" (the std left out when it is 0, e.g. one seed); "" for no value."""
    if stat is None:
        return ""
    scale = 100.0 if pct else 1.0
    text = f"{stat.mean * scale:.{digits}f}"
    return text + (f" ± {stat.std * scale:.{digits}f}" if stat.std else "")


@dataclasses.dataclass(frozen=True)
class Column:
    """A trade-off table column: header and cell(entry, attacks) where `attacks` (None: all) limits
    the worst case to some attackers (the web page's threat-model filter)."""

    header: str
    cell: Callable[[Entry, set[str] | None], Cell]


def _text(get: Callable[[Entry], str]) -> Callable[[Entry, set[str] | None], Cell]:
    return lambda e, attacks: (get(e), None)


def _utility(name: str) -> Callable[[Entry, set[str] | None], Cell]:
    def cell(e: Entry, attacks: set[str] | None) -> Cell:
        stat = e.metric("utility", name)
        return pm(stat), None if stat is None else stat.mean
    return cell


def _worst(name: str, kind: str, digits: int, pct: bool = False, named: bool = True
           ) -> Callable[[Entry, set[str] | None], Cell]:
    def cell(e: Entry, attacks: set[str] | None) -> Cell:
        found = e.worst_case(name, kind, attacks)
        if found is None:
            return "", None
        stat, attack = found
        return (f"{pm(stat, digits, pct)} ({attack})" if named else pm(stat, digits, pct)), stat.mean
    return cell


def _single(attack: str, name: str, fmt: str) -> Callable[[Entry, set[str] | None], Cell]:
    def cell(e: Entry, attacks: set[str] | None) -> Cell:
        stat = e.metric(attack, name)
        return ("", None) if stat is None else (format(stat.mean, fmt), stat.mean)
    return cell


MAIN_COLUMNS = (
    Column("lens", _text(lambda e: e.lens)),
    Column("profile", _text(lambda e: e.profile)),
    Column("scenes", _text(lambda e: e.scenes)),
    Column("seeds", _text(lambda e: ",".join(map(str, e.seeds)))),
    Column("mIoU", _utility("miou")),
    Column("mA", _utility("mean_acc")),
    Column("OA", _utility("overall_acc")),
    Column("worst PSNR dB (attacker)", _worst("psnr_db", "restorer", 2)),
    Column("worst SSIM", _worst("ssim", "restorer", 3, named=False)),
    Column("worst plate acc % (chain)", _worst("plate_acc", "reader", 1, pct=True)),
    Column("W_5% px (T=1)", _single("bound", "bound_width_eps_t1", ".0f")),
    Column("lens img/s", _single("lens", "images_per_s", ".1f")),
)


def _markdown(head: Sequence[str], lines: Sequence[Sequence[str]]) -> str:
    out = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * len(head)) + "|"]
    return "\n".join(out + ["| " + " | ".join(cells) + " |" for cells in lines])


def main_table(entries: Sequence[Entry]) -> str:
    """Utility against the worst case of every attacker, one line per entry (markdown)."""
    return _markdown([c.header for c in MAIN_COLUMNS],
                     [[c.cell(e, None)[0] for c in MAIN_COLUMNS] for e in entries])


def findings_table(entries: Sequence[Entry]) -> str:
    """The paper's findings checked per profile (benchmark.findings), or "" when none applies."""
    found = check_findings(entries)
    if not found:
        return ""
    return _markdown(["profile", "finding", "a", "b", "a", "b", "a - b", "verdict"],
                     [[f.profile, f.claim, f.lens_a, f.lens_b, pm(f.a), pm(f.b), f"{f.difference:+.3f}", f.verdict]
                      for f in found])


def attacker_table(entries: Sequence[Entry]) -> str:
    """Every attack chain of every entry with its own figures (markdown)."""
    lines = []
    for e in entries:
        for chain in e.chains():
            if chain.kind in ("lens", "utility", "bound"):
                continue
            m = chain.metrics.get
            fit, speed = m("fit_s"), m("images_per_s")
            lines.append([e.lens, chain.attack, ",".join(map(str, chain.seeds)), chain.threat_model or "",
                          pm(m("psnr_db"), 2), pm(m("ssim")), pm(m("plate_acc"), 1, pct=True), pm(m("plate_cer")),
                          f"{fit.mean:.1f}" if fit else "", f"{speed.mean:.2f}" if speed else ""])
    return _markdown(["lens", "attack", "seeds", "threat model", "PSNR dB", "SSIM", "plate acc %", "plate CER",
                      "fit s", "img/s"], lines)
