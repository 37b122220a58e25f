"""The standard-ensemble study: docs/ensemble.md from the published quick entries.

    python -m benchmark.studies.ensemble_choice_study [--dir leaderboard] [--out docs/ensemble.md]

Writes which chains decide a plate (first or only reader) or a scene (its best restorer) on each
published quick entry, every chain's removal effect on its lens's ensemble plate accuracy and
ensemble PSNR, the rule and the ensemble it selects (benchmark.results.ensemble_choice), with the date
and the entries (file and SHA-256) it was computed from. The test
(tests/benchmark/results/test_ensemble_choice.py) re-renders it from the entries and compares all but the date.
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import json
from collections.abc import Sequence
from pathlib import Path

from benchmark.results.ensemble_choice import (PLATE_POINTS, PSNR_DB, ChainEffect, ensemble_values, keeps,
                                               proposed_ensemble, removal_effects, strongest_restorer)
from benchmark.runner.defaults import LEARNED_READER, PROPOSED_ENSEMBLE
from benchmark.results.entries import LEADERBOARD, Entry, display_order, read_entry
from benchmark.results.markdown import md_cell
from benchmark.store.cache import atomic_write_text

DOC = Path(__file__).resolve().parents[2] / "docs" / "ensemble.md"
PROFILE = "quick"
DATE_PREFIX = "Computed on "


def quick_entries(directory: Path = LEADERBOARD) -> list[tuple[Path, Entry]]:
    """The published entries of the quick profile (`entries/*quick*.json` whose profile is quick), in
    the leaderboard's display order, with their files."""
    found = [(p, read_entry(p)) for p in sorted((directory / "entries").glob(f"*{PROFILE}*.json"))]
    found = [(p, e) for p, e in found if e.profile == PROFILE]
    order = display_order([e for _, e in found])
    return sorted(found, key=lambda pe: next(i for i, e in enumerate(order) if e is pe[1]))


def _table(head: Sequence[str], lines: Sequence[Sequence[object]]) -> str:
    out = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * len(head)) + "|"]
    return "\n".join(out + ["| " + " | ".join(md_cell(c) for c in line) + " |" for line in lines])


def _signed(value: float, digits: int) -> str:
    return "inf" if value == float("inf") else f"{value + 0.0:+.{digits}f}"  # + 0.0: no "-0.00" for -0.0


def _summary(effects: list[ChainEffect], proposed: Sequence[str]) -> str:
    lines = []
    for attack in dict.fromkeys(e.attack for e in effects):
        mine = [e for e in effects if e.attack == attack]
        plates = max(mine, key=lambda e: abs(e.plate_points))
        psnr = max(mine, key=lambda e: abs(e.psnr_db))
        kind = mine[0].kind
        lines.append([
            f"`{attack}`", "reader chain" if kind == "plates" else "restorer", len(mine),
            sum(e.first for e in mine) if kind == "plates" else "", sum(e.only for e in mine) if kind == "plates" else "",
            sum(e.best_scenes for e in mine) if kind == "scenes" else "",
            f"{_signed(plates.plate_points, 2)} ({plates.lens})" if kind == "plates" else "",
            f"{_signed(psnr.psnr_db, 3)} ({psnr.lens})" if kind == "scenes" else "",
            "yes" if any(e.matters for e in mine) else "no", "yes" if attack in proposed else "no"])
    lines.sort(key=lambda line: (line[1], line[-1] == "no", str(line[0])))
    return _table(["chain", "kind", "entries", "plates read first", "plates only it read", "scenes it is best on",
                   "largest removal effect, plate acc pt (lens)", "largest removal effect, PSNR dB (lens)",
                   "rule keeps it", "proposed"], lines)


def _details(effects: list[ChainEffect]) -> str:
    lines = [[e.lens, f"`{e.attack}`", e.first if e.kind == "plates" else "", e.only if e.kind == "plates" else "",
              e.best_scenes if e.kind == "scenes" else "",
              _signed(e.plate_points, 2) if e.kind == "plates" else "",
              _signed(e.psnr_db, 3) if e.kind == "scenes" else "", "yes" if e.matters else "no"]
             for e in effects if e.decides or e.matters]
    return _table(["lens", "chain", "plates read first", "plates only it read", "scenes it is best on",
                   "removal effect, plate acc pt", "removal effect, PSNR dB", "past the rule"], lines)


def _joint(entries: Sequence[Entry], proposed: Sequence[str]) -> str:
    lines = []
    for e in entries:
        (p_all, s_all), (p_std, s_std) = ensemble_values(e), ensemble_values(e, set(proposed))
        lines.append([e.lens, ",".join(map(str, e.seeds)),
                      "" if p_all is None else f"{p_all:.2f}", "" if p_std is None else f"{p_std:.2f}",
                      "" if p_all is None or p_std is None else _signed(p_std - p_all, 2),
                      "" if s_all is None else f"{s_all:.3f}", "" if s_std is None else f"{s_std:.3f}",
                      "" if s_all is None or s_std is None else _signed(s_std - s_all, 3)])
    return _table(["lens", "seeds", "plate acc %, every chain", "plate acc %, proposed", "change pt",
                   "PSNR dB, every restorer", "PSNR dB, proposed", "change dB"], lines)


def render(directory: Path = LEADERBOARD, date: str | None = None) -> str:
    """docs/ensemble.md's text from the quick entries of `directory` (today's date unless given)."""
    found = quick_entries(directory)
    entries = [e for _, e in found]
    effects = removal_effects(entries)
    proposed = proposed_ensemble(effects)
    strongest = strongest_restorer(effects)
    kept = keeps(effects)
    date = date or datetime.date.today().isoformat()
    listed = [f"- `{p.relative_to(directory.parent) if directory.parent in p.parents else p.name}` "
              f"(seeds {','.join(map(str, e.seeds))}; SHA-256 {hashlib.sha256(p.read_bytes()).hexdigest()[:16]})"
              for p, e in found]
    deciders = sorted({e.attack for e in effects if e.decides})
    never = sorted({e.attack for e in effects} - set(deciders))
    dropped = sorted({e.attack for e in effects} - set(proposed))
    drift = "" if tuple(proposed) == PROPOSED_ENSEMBLE else (
        "\n**`PROPOSED_ENSEMBLE` in benchmark/runner/defaults.py differs from what the rule selects "
        "here: update it.**\n")
    return "\n".join([
        "# The standard attack ensemble: which chains decide", "",
        "Generated by `python -m benchmark.studies.ensemble_choice_study` (benchmark/results/ensemble_choice.py); "
        "never edited by hand.", "",
        f"{DATE_PREFIX}{date} from the published {PROFILE} entries:", "", *listed, "",
        "## What is measured", "",
        "Privacy is the ensemble's (docs/results.md): a plate counts as read when any reader chain of the lens "
        "read it exactly (pooled over seeds), a scene counts at its best restorer (mean over seeds of the mean "
        "over scenes of the per-scene best PSNR). For every chain of every entry: the plates it read **first** "
        "(the first chain, in the entry's chain order, i.e. the order its run evaluated them, that read the "
        "plate), the plates **only** it read, the scenes where it is the best restorer, and its **removal "
        "effect**: the ensemble's plate accuracy (points) and PSNR (dB) with it minus without it (the ensemble "
        "recomputed from the other chains' per-unit outcomes). Reference rows (`raw>...`) are not attackers "
        "and take no part.", "",
        "## The rule", "",
        f"Keep every chain whose removal changes some lens's ensemble plate accuracy by more than {PLATE_POINTS:g} "
        f"point or its ensemble PSNR by more than {PSNR_DB:g} dB. Add `lpdr` (the paper's detector pipeline) on "
        f"the sensor image and after the strongest restorer (the best restorer on the most scenes of these "
        f"entries: `{strongest}`), and `learned-reader` (the learned reader of the privacy-range issue), which "
        + ("the rule keeps on its own here." if LEARNED_READER in kept else "these entries do not hold."), "",
        "## The proposed standard ensemble", "",
        f"{len(proposed)} chains: " + ", ".join(f"`{a}`" for a in proposed) + ".", "",
        f"The rule alone keeps {len(kept)}: " + ", ".join(f"`{a}`" for a in sorted(kept)) + ".", "",
        "Chains that never decide a plate or a scene on any entry: " + (", ".join(f"`{a}`" for a in never) or "none")
        + ".", "",
        f"Left out of the proposal ({len(dropped)}): " + (", ".join(f"`{a}`" for a in dropped) or "none") + ".", "",
        "This is `benchmark.runner.defaults.PROPOSED_ENSEMBLE`. Runs measured it with the attackers newer than "
        "these entries that were measured stronger (`MEASURED_ADDITIONS`: restorers; `MEASURED_READERS`: readers "
        "whose addition raised these entries' ensemble on their own plates) and last the cascade (`CASCADE`: the "
        "maximum-likelihood reader on the plates no chain before it read, benchmark.runner.cascade); the rule, "
        "applied again to fresh runs of that set (below), chose the run's default, `STANDARD_ENSEMBLE` "
        "(`RUN_PROPOSAL` and the `raw` reference, the uncorrected image's PSNR, read by no chain): "
        "`python -m benchmark run` measures those chains only, "
        "`--attack NAME` exactly the attackers named (every reader after every restorer), `--all-chains` the full "
        "cross product of the attackers that run by default. Entries published before the standard ensemble "
        "hold the full cross product until `python -m benchmark publish` replaces them; those re-published with "
        "it hold only its chains, so a chain left out of it can no longer show that it decides there.",
        drift,
        *_fresh_runs(directory),
        "## Every chain", "",
        "Summed over the entries it ran on; the largest removal effect over them, with its lens.", "",
        _summary(effects, proposed), "",
        "## Per lens: the chains that decide", "",
        "Every chain of every entry that decides a plate or a scene, or whose removal passes the rule.", "",
        _details(effects), "",
        "## The proposed ensemble against every chain, per lens", "",
        "The removal effects above are one chain at a time; chains that read the same plates can each be "
        "harmless to remove and not together. This is the ensemble restricted to the proposed chains (those of "
        "them each entry has) against the ensemble of every chain.", "",
        _joint(entries, proposed), "", _joint_verdict(entries, proposed), ""])


def _fresh_runs(directory: Path) -> list[str]:
    """The section on the rule re-applied to fresh runs (``leaderboard/studies/run_pairing.json``'s
    ``proposal``, ``python -m benchmark.studies.run_pairing_study --run ...``); nothing without one."""
    path = directory / "studies" / "run_pairing.json"
    record = json.loads(path.read_text()) if path.exists() else {}
    proposal = record.get("proposal")
    if not proposal:
        return []
    lines = []
    for lens in proposal["lenses"]:
        run = record["lenses"][lens]
        effects = run["chain_effects"]
        joint = proposal["joint_removal"].get(lens, {})
        lines.append([lens, ", ".join(sorted({p.split()[-1] for p in run.get("run_provenance", [])})),
                      "; ".join(f"`{c}` {_signed(e['plate_points'], 2)} pt" if e["kind"] == "plates"
                                else f"`{c}` {_signed(e['psnr_db'], 3)} dB" for c, e in effects.items() if e["matters"]),
                      "" if joint.get("plate_points") is None else _signed(-joint["plate_points"], 2),
                      "" if joint.get("psnr_db") is None else _signed(-joint["psnr_db"], 3)])
    added = proposal.get("added_jointly", [])
    return ["## Re-chosen on fresh runs", "",
            f"The rule applied to fresh runs of {', '.join(proposal['lenses'])} at seed 0 "
            "(`leaderboard/studies/run_pairing.json`, `python -m benchmark.studies.run_pairing_study --run ...`; the "
            "runs' results are kept in `leaderboard/studies/cross_product`). A chain none of these runs held had no "
            "say. The cascade reads only the plates the chains before it missed, so a chain's removal effect "
            "overstates what dropping it costs (the cascade would then read some of its plates).", "",
            _table(["lens", "run (date)", "chains past the rule: removal effect",
                    "every dropped chain removed at once, plate acc pt", "the same, PSNR dB"], lines), "",
            f"Strongest restorer: `{proposal['strongest_restorer']}`. The rule keeps "
            + ", ".join(f"`{c}`" for c in proposal.get("rule", proposal["chains"])) + ". "
            + ("Chains that each decide nothing alone read plates together (the same reader after several "
               "restorers, each near its threshold on a few plates): with the rule's chains alone the runs lost "
               + "; ".join(f"{lens} {v['plate_points']:.2f} pt" for lens, v in proposal.get("rule_joint_removal", {}).items()
                           if v.get("plate_points") is not None)
               + " of their plates (from every width), so the chains that recover most per measured second were added one at a "
               "time (`complete_ensemble` in benchmark/results/ensemble_choice.py) until none did: "
               + ", ".join(f"`{c}`" for c in added) + ", with the restorers they read. " if added else "")
            + f"Kept ({len(proposal['chains'])}): " + ", ".join(f"`{c}`" for c in proposal["chains"])
            + f". Dropped ({len(proposal['dropped'])}): " + ", ".join(f"`{c}`" for c in proposal["dropped"])
            + ". This is `benchmark.runner.defaults.RUN_PROPOSAL`.", ""]


def _joint_verdict(entries: Sequence[Entry], proposed: Sequence[str]) -> str:
    """One generated sentence: the lenses where the proposal, all dropped chains removed at once, moves the
    ensemble past the rule's thresholds (or that none does)."""
    past = []
    for e in entries:
        (p_all, s_all), (p_std, s_std) = ensemble_values(e), ensemble_values(e, set(proposed))
        if p_all is not None and p_std is not None and abs(p_std - p_all) > PLATE_POINTS:
            past.append(f"{e.lens} {p_std - p_all:+.2f} pt")
        if s_all is not None and s_std is not None and abs(s_std - s_all) > PSNR_DB:
            past.append(f"{e.lens} {s_std - s_all:+.3f} dB")
    if not past:
        return ("With every left-out chain removed at once, no lens's ensemble moves by more than the rule's "
                "thresholds.")
    return ("**With every left-out chain removed at once, the ensemble moves past the rule's thresholds on: "
            + "; ".join(past) + ".** The one-at-a-time rule understates what the left-out chains read together; "
            "before the proposal becomes the default, either keep the chains that restore these plates or state "
            "the loss beside the re-published figures.")


def date_of(text: str) -> str | None:
    """The date a rendered docs/ensemble.md states (None if it states none)."""
    for line in text.splitlines():
        if line.startswith(DATE_PREFIX):
            return line[len(DATE_PREFIX):].split(" ", 1)[0]
    return None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmark.studies.ensemble_choice_study", description=__doc__)
    parser.add_argument("--dir", type=Path, default=LEADERBOARD, help="leaderboard folder")
    parser.add_argument("--out", type=Path, default=DOC, help="the markdown file to write")
    args = parser.parse_args(argv)
    text = render(args.dir)
    atomic_write_text(args.out, text)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
