"""Render the leaderboard from its entries alone (`python -m benchmark report`): README.md (tables),
charts/*.png and index.html (the web page).

Rendering holds the leaderboard folder's lock (``benchmark.results.entries.locked``), which publishing
holds from reading the stored entries to its own render (benchmark.publish.leaderboard): a render that
read the entries before a concurrent publish wrote its rows must not write its pages after that publish's.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from pathlib import Path

from benchmark.store.cache import atomic_write_text
from benchmark.results.charts import save_figure
from benchmark.results.charts.attacker_speed import write_attacker_speed_chart
from benchmark.publish.profile_chart import write_profile_chart
from benchmark.results.charts.tradeoff import PLATES_LABEL, PSNR_LABEL, write_tradeoff_chart
from benchmark.results.entries import LEADERBOARD, Entry, display_order, load_entries, locked
from benchmark.publish import board_files
from benchmark.publish.page import write_page
from benchmark.publish.versions import Apart, board_split
from benchmark.publish.tables import (CONVENTION, bracket_lines, ensemble_summary, findings_table, flags_table, main_table,
                                      readme_table, takeaways, violations_table)
from benchmark.results.attack_gap import CEILING_ALARM, GAP_ALARM, Flag, entry_flags
from benchmark.results.observer.published import entry_violations, load_study

log = logging.getLogger(__name__)

INTRO = ("Rendered by `python -m benchmark report` from `leaderboard/entries/*.json` (written by "
         "`python -m benchmark run ... --publish`); never edited by hand. Privacy is the ensemble's, the per-unit "
         "worst case over every attacker of the suite for that lens (benchmark.results.ensemble): a plate counts as "
         "read when any reader chain read it exactly "
         "(Wilson interval on the plates of every seed pooled), a scene counts at its best restorer (scene "
         "bootstrap); reference rows (the uncorrected `raw` image) are not attackers and stay out. Worst case = the "
         "strongest single attacker (ranked on the seeds every attacker ran, then shown over all of its seeds), "
         "beside it. Attack gap = the ideal observer's ceiling at the bin's smallest width minus the ensemble's "
         "accuracy in the bin (entries without per-plate widths: every readable plate from 32 px, so the gap is a "
         "lower bound); W_5% = the plate width below which "
         "the attack-independent bound certifies that no attacker reads more than 5 % of plates: Fano = the Gaussian "
         "information bound (lenses.bound), ideal observer = the Bayesian ideal observer's ceiling "
         "(benchmark.results.observer, `studies/ideal_observer.json`, T = 1 and 30 frames), shown only where the study "
         "used the entry's own lens spec (else \"not computed\"); ceiling % at 32 px = the most any attacker can "
         "read of 32 px plates exactly. Publishing merges "
         "with a stored entry of the same lens and profile: an attacker row keeps the seeds (listed in the attacker "
         "table) and the provenance of the run that measured it. Findings are decided by paired comparisons on the "
         "same scenes and plates (benchmark.publish.findings): paired bootstrap (stratified by seed) for mIoU and the "
         "ensemble's PSNR (each scene at its best restorer), McNemar's exact test on the ensemble's per-plate reads; "
         "'cannot tell' where the sample cannot separate the lenses or an entry carries no per-unit outcomes.")


def flags_text(flags: list[Flag]) -> list[str]:
    """The README's "Attack flags" section (never left out: it says so when there are none)."""
    intro = ("In the spirit of AutoAttack (benchmark.results.attack_gap): a reader above the ceiling, a learned "
             "attacker whose fit was still improving (row note `fit_still_rising`), an attacker that does not learn "
             "the lens beating one of its family that does (paired test, 5 %), and an attack gap over "
             f"{100 * GAP_ALARM:.0f} points where the ceiling exceeds {100 * CEILING_ALARM:.0f} % (the suite's "
             "attackers are weak there: privacy is overstated).")
    return [intro, "", flags_table(flags) if flags else "None."]


def study_charts(directory: Path, charts: Path) -> list[Path]:
    """Charts of the modelling-choice studies found in `directory`/studies (see benchmark.studies)."""
    from benchmark.results.charts.nafnet_steps_chart import write_nafnet_steps_chart
    from benchmark.results.charts.studies import psf_grid_figure, utility_size_figure
    from benchmark.results.charts.utility_pretrain import pretrain_figure
    written = []
    for name, figure in (("psf_grid", psf_grid_figure), ("utility_size", utility_size_figure),
                         ("utility_pretrain", pretrain_figure)):
        path = directory / "studies" / f"{name}.json"
        if path.is_file():
            written.append(save_figure(figure(json.loads(path.read_text())), charts / f"{name}.png", dpi=100))
    steps = directory / "studies" / "nafnet_known_pairs_steps.json"  # written by benchmark.studies.nafnet_steps_study
    if steps.is_file():
        written.append(write_nafnet_steps_chart(json.loads(steps.read_text()), charts / f"{steps.stem}.png"))
    return written


def entry_charts(entries: list[Entry], charts: Path, study: dict | None = None) -> list[Path]:
    """The leaderboard's charts of its entries (those with data to show)."""
    return [p for p in (
        write_tradeoff_chart(entries, charts / "utility_vs_psnr.png", "psnr_db", PSNR_LABEL),
        write_tradeoff_chart(entries, charts / "utility_vs_plates.png", "plate_acc", PLATES_LABEL, 100.0, study),
        write_attacker_speed_chart(entries, charts / "attackers_speed_vs_psnr.png"),
        write_profile_chart(entries, charts / "profiles.png"),
    ) if p is not None]


def observer_chart(directory: Path, entries: list[Entry], charts: Path) -> list[Path]:
    """The ideal-observer ceiling against plate width with the entries' readers on it (if the study exists)."""
    from benchmark.results.charts.ideal_observer_chart import write_ideal_observer_chart
    study = load_study(directory)
    return [] if study is None else [write_ideal_observer_chart(study, entries, charts / "ideal_observer.png")]


def violations_text(found: list) -> list[str]:
    """The README's "Ceiling violations" section (never left out: it says so when there are none)."""
    if not found:
        return ["None: every reader of every entry whose lens the ideal-observer study covers reads at or below its "
                "ceiling (T = 1, upper 95 % limit; the reader's accuracy over all readable plates, Wilson 95 %)."]
    return [f"**{len(found)} reader(s) beat the ideal observer's ceiling: a modelling or scoring error "
            "(benchmark.results.observer.consistency).**", "", violations_table(found)]


def apart_text(apart: Sequence[Apart], study: dict | None = None) -> list[str]:
    """The README's "Shown apart" section: entries of another version than their board's, marked, with their
    figures in a table of their own (empty when there are none)."""
    if not apart:
        return []
    return ["## Shown apart: entries of another version", "",
            "Measured by another code version, torch version or plate definition than their profile's board "
            "(benchmark.publish.versions): they enter no takeaway, Pareto front, finding, chart or bracket above "
            "until re-published (`python -m benchmark publish --lens LENS`).", "",
            *[f"- **{a.entry.lens}** ({a.entry.profile}): {a.reason}." for a in apart], "",
            main_table([a.entry for a in apart], study), ""]


def readme_text(entries: list[Entry], charts: list[Path], pictures: list[Path], study: dict | None = None,
                violations: list | None = None, flags: list[Flag] | None = None, apart: Sequence[Apart] = ()
                ) -> str:
    """The leaderboard README: tables (`entries`: the board's version; `apart`: the others, marked), then the
    charts and the published pictures (paths relative)."""
    findings = findings_table(entries)
    summary = ensemble_summary(entries)
    said = [f"**Takeaway ({profile}).** {line}" for profile, line in takeaways(entries, study).items()]
    text = ["# Leaderboard", "", f"**Intervals.** {CONVENTION}", "", INTRO, "",
            *[x for line in said for x in (line, "")],
            "The same tables, sortable and filterable by profile, scenes and threat model, with interactive "
            "charts: [index.html](index.html) (a self-contained page; open it from disk).", "",
            "## Utility against privacy", "", main_table(entries, study), "", *([summary, ""] if summary else []),
            *(["## Privacy, bracketed", "", "What the suite's attackers read of every readable plate (the tables' "
               "figure) against what the ideal observer reads of the same plates (the mean of each plate's ceiling "
               "at its width, the tighter one where the study has it; benchmark.results.attack_gap.pooled_bracket), "
               "one frame:", "", *brackets, ""] if (brackets := bracket_lines(entries, study)) else []),
            *apart_text(apart, study),
            "## Ceiling violations", "", *violations_text(violations or []), "",
            "## Attack flags", "", *flags_text(flags or []), "",
            *(["## The paper's findings on these entries", "", findings, ""] if findings else []),
            "## The rest", "",
            f"- [Every attacker]({board_files.ATTACKERS_PAGE}): each chain's part in its lens's ensemble and every "
            "attacker's own figures;",
            f"- [Charts and samples]({board_files.CHARTS_PAGE}): {len(charts)} charts, plate accuracy against width "
            f"per entry, {len(pictures)} sample pictures;",
            "- [index.html](index.html): the same, sortable and filterable;",
            "- [docs/ensemble.md](../docs/ensemble.md): which chains decide the ensemble, and the proposed standard one."]
    return "\n".join(text) + "\n"


def render(directory: Path = LEADERBOARD) -> list[Path]:
    """Write README.md, charts/*.png and index.html of the leaderboard in `directory` from its entries
    (holding its lock, see the module docstring)."""
    with locked(directory):
        return _render(directory)


def _render(directory: Path) -> list[Path]:
    every = display_order(load_entries(directory))
    board = board_split(every)
    entries = board.current  # what the board compares: its version's entries only (benchmark.publish.versions)
    charts = directory / "charts"
    charts.mkdir(parents=True, exist_ok=True)
    study = load_study(directory)
    written = entry_charts(entries, charts, study) + study_charts(directory, charts) + observer_chart(directory,
                                                                                                     entries, charts)
    widths = board_files.plate_width_charts(every, charts)
    pictures = board_files.backed_samples(every, directory / "samples")
    board_files.prune(directory, [*written, *widths, *pictures])  # what no entry or study backs
    violations = entry_violations(every, study)  # each one logged as an ERROR there
    flags = entry_flags(every, study)
    for flag in flags:
        log.warning("attack flag: %s", flag.text())
    readme = directory / "README.md"
    atomic_write_text(readme, readme_text(entries, written + widths, pictures, study, violations, flags, board.apart))
    pages = board_files.write_pages(directory, every, written, widths, pictures)
    page = write_page(directory / "index.html", entries, written + widths, pictures, study, violations, flags,
                      board.apart)
    for path in (readme, *pages, *written, *widths, page):
        log.debug("wrote %s", path)
    return [readme, *pages, *written, *widths, page]


README_START, README_END = "<!-- results:start -->", "<!-- results:end -->"


def update_readme(readme: Path, directory: Path = LEADERBOARD) -> bool:
    """Replace the short results table (`tables.readme_table`, the quick entries) between the markers of the
    project README (if present; False when not), holding the leaderboard's lock (a concurrent publish must not be overwritten by an older table)."""
    with locked(directory):
        return _update_readme(readme, directory)


def _update_readme(readme: Path, directory: Path) -> bool:
    text = readme.read_text()
    if README_START not in text or README_END not in text:
        return False
    head, rest = text.split(README_START, 1)
    _, tail = rest.split(README_END, 1)
    section = readme_results(display_order(load_entries(directory)), load_study(directory))
    atomic_write_text(readme, f"{head}{README_START}\n{section}\n{README_END}{tail}")
    return True


def readme_results(entries: Sequence[Entry], study: dict | None = None) -> str:
    """The project README's results: the short table of the quick board's entries of its version
    (`tables.readme_table`), then the quick entries shown apart (benchmark.publish.versions), named."""
    board = board_split(entries)
    apart = [a.entry.lens for a in board.apart if a.entry.profile == "quick"]
    note = (f"\n\nNot in this table until re-published (another version, shown apart on the leaderboard): "
            f"{', '.join(apart)}." if apart else "")
    return readme_table(board.current, study) + note
