"""Render leaderboard/README.md and its charts from the entries alone (`python -m benchmark report`)."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from benchmark.cache import atomic_write_text  # noqa: E402
from benchmark.charts import save_figure  # noqa: E402
from benchmark.leaderboard import LEADERBOARD, load_entries, metric, worst_case  # noqa: E402

# Fixed metadata so that the same entries give byte-identical PNGs.
_PNG_META = {"Software": None}


def _save(fig: plt.Figure, path: Path) -> Path:
    """Write a chart with fixed metadata (byte-identical re-renders) and free the figure."""
    return save_figure(fig, path, dpi=100, metadata=_PNG_META)


def _pm(value: tuple[float, float] | tuple[float, float, str] | None, digits: int = 3, pct: bool = False) -> str:
    if value is None:
        return ""
    mean, std = value[0], value[1]
    scale = 100.0 if pct else 1.0
    text = f"{mean * scale:.{digits}f}"
    return text + (f" ± {std * scale:.{digits}f}" if std else "")


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of points not dominated when minimising x (attacker strength) and maximising y (utility)."""
    front = []
    for i, (x, y) in enumerate(points):
        if not any((x2 <= x and y2 >= y) and (x2 < x or y2 > y) for j, (x2, y2) in enumerate(points) if j != i):
            front.append(i)
    return sorted(front, key=lambda i: points[i][0])


def main_table(entries: list[dict]) -> str:
    head = ("| lens | profile | scenes | seeds | mIoU | mA | OA | worst PSNR dB (attacker) | worst SSIM | "
            "worst plate acc % (chain) | W_5% px (T=1) | lens img/s |")
    lines = [head, "|" + "|".join(["---"] * (head.count("|") - 1)) + "|"]
    for e in entries:
        psnr = worst_case(e, "psnr_db", "restorer")
        ssim = worst_case(e, "ssim", "restorer")
        plate = worst_case(e, "plate_acc", "reader")
        width = metric(e, "bound", "bound_width_eps_t1")
        speed = metric(e, "lens", "images_per_s")
        lines.append("| " + " | ".join([
            e["lens"], e["profile"], e["scenes"], ",".join(map(str, e["seeds"])),
            _pm(metric(e, "utility", "miou")), _pm(metric(e, "utility", "mean_acc")), _pm(metric(e, "utility", "overall_acc")),
            f"{_pm(psnr, 2)} ({psnr[2]})" if psnr else "", _pm(ssim) if ssim else "",
            f"{_pm(plate, 1, pct=True)} ({plate[2]})" if plate else "",
            f"{width[0]:.0f}" if width else "", f"{speed[0]:.1f}" if speed else ""]) + " |")
    return "\n".join(lines)


# The paper's qualitative claims, as (claim, lens a, lens b, metric, kind, expected sign of a - b).
# kind "utility" reads the utility row, "restorer" the strongest restorer's figure.
PAPER_FINDINGS = (
    ("more lambda_deb costs utility", "os-d-1", "os-d-1000", "miou", "utility", +1),
    ("more lambda_deb lowers the attacker's PSNR", "os-d-1", "os-d-1000", "psnr_db", "restorer", +1),
    ("GP gives lambda_deb = 1000 privacy (attacker PSNR no higher)", "gp", "os-d-1000", "psnr_db", "restorer", 0),
    ("GP keeps more utility than lambda_deb = 1000", "gp", "os-d-1000", "miou", "utility", +1),
    ("MTAdam gives weaker privacy than lambda_deb = 1000", "os-d-mtadam", "os-d-1000", "psnr_db", "restorer", +1),
)


def _finding_value(entry: dict, name: str, kind: str, attacks: set[str]) -> tuple[float, float] | None:
    """The utility metric, or the strongest attacker's figure among ``attacks`` (those both lenses met)."""
    if kind == "utility":
        found = metric(entry, "utility", name)
    else:
        found = worst_case({**entry, "rows": [r for r in entry["rows"] if r["attack"] in attacks]}, name, kind)
    return None if found is None else (found[0], found[1])


def findings_table(entries: list[dict]) -> str:
    """The paper's qualitative findings checked on the entries of each profile (computed, not typed).

    Attacker figures are the strongest attacker among those that ran on both lenses, so that a
    richer attacker set on one side does not decide the comparison. A difference counts as within noise when it is smaller than the two seed spreads added (or
    when either side has a single seed, which gives no spread: then the verdict says so).
    "No higher" claims (sign 0) hold when a - b <= the spreads added.
    """
    head = "| profile | finding | a | b | a | b | a - b | verdict |"
    lines = [head, "|" + "|".join(["---"] * (head.count("|") - 1)) + "|"]
    by_key = {(e["lens"], e["profile"]): e for e in entries}
    for profile in dict.fromkeys(e["profile"] for e in entries):
        for claim, a, b, name, kind, sign in PAPER_FINDINGS:
            if (a, profile) not in by_key or (b, profile) not in by_key:
                continue
            common = ({r["attack"] for r in by_key[a, profile]["rows"]}
                      & {r["attack"] for r in by_key[b, profile]["rows"]})
            va = _finding_value(by_key[a, profile], name, kind, common)
            vb = _finding_value(by_key[b, profile], name, kind, common)
            if va is None or vb is None:
                continue
            diff, noise = va[0] - vb[0], va[1] + vb[1]
            one_seed = len(by_key[a, profile]["seeds"]) < 2 or len(by_key[b, profile]["seeds"]) < 2
            if sign == 0:
                verdict = "holds" if diff <= noise else "does not hold"
            elif abs(diff) <= noise:
                verdict = "within seed noise"
            else:
                verdict = "holds" if diff * sign > 0 else "does not hold"
            if one_seed and verdict != "within seed noise":
                verdict += " (one seed: no spread)"
            lines.append(f"| {profile} | {claim} | {a} | {b} | {_pm(va, 3)} | {_pm(vb, 3)} | {diff:+.3f} | {verdict} |")
    return "\n".join(lines) if len(lines) > 2 else ""


def attacker_table(entries: list[dict]) -> str:
    head = "| lens | attack | seeds | threat model | PSNR dB | SSIM | plate acc % | plate CER | fit s | img/s |"
    lines = [head, "|" + "|".join(["---"] * (head.count("|") - 1)) + "|"]
    for e in entries:
        for row in e["rows"]:
            if row["attack"] in ("lens", "utility", "bound"):
                continue
            m = lambda name: metric(e, row["attack"], name)  # noqa: E731
            fit, speed = m("fit_s"), m("images_per_s")
            lines.append("| " + " | ".join([
                e["lens"], row["attack"], ",".join(map(str, row["seeds"])), row.get("threat_model", ""),
                _pm(m("psnr_db"), 2), _pm(m("ssim")),
                _pm(m("plate_acc"), 1, pct=True), _pm(m("plate_cer")), f"{fit[0]:.1f}" if fit else "",
                f"{speed[0]:.2f}" if speed else ""]) + " |")
    return "\n".join(lines)


def tradeoff_chart(entries: list[dict], path: Path, privacy: str, kind: str, xlabel: str, scale: float = 1.0) -> Path | None:
    pts, labels, errs, profiles = [], [], [], []
    for e in entries:
        util, worst = metric(e, "utility", "miou"), worst_case(e, privacy, kind)
        if util is None or worst is None:
            continue
        pts.append((worst[0] * scale, util[0]))
        errs.append((worst[1] * scale, util[1]))
        labels.append(f"{e['lens']} ({e['profile']})")
        profiles.append(e["profile"])
    if not pts:
        return None
    fig, ax = plt.subplots(figsize=(7, 5))
    for (x, y), (ex, ey), label in zip(pts, errs, labels):
        ax.errorbar(x, y, xerr=ex or None, yerr=ey or None, fmt="o", capsize=3)
        ax.annotate(label, (x, y), textcoords="offset points", xytext=(5, 4), fontsize=8)
    for profile in dict.fromkeys(profiles):  # a front per profile: budgets are not comparable
        members = [i for i, p in enumerate(profiles) if p == profile]
        front = [members[i] for i in pareto_front([pts[i] for i in members])]
        ax.plot([pts[i][0] for i in front], [pts[i][1] for i in front], "--", lw=1, label=f"Pareto front ({profile})")
    ax.set_xlabel(xlabel + " (lower = more private)")
    ax.set_ylabel("utility mIoU (higher = more useful)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path)


def attacker_speed_chart(entries: list[dict], path: Path) -> Path | None:
    """Attackers' speed against accuracy: restorers (images/s vs PSNR) and plate readers (images/s vs
    plate accuracy, chains included), one point per lens."""
    panels = (("psnr_db", 1.0, "PSNR dB against the sharp scene", "Restorers"),
              ("plate_acc", 100.0, "plate accuracy %", "Plate readers and chains"))
    series = [{} for _ in panels]
    for e in entries:
        for row in e["rows"]:
            mt = row["metrics"]
            for (name, scale, _, _), found in zip(panels, series):
                if name in mt and "images_per_s" in mt:
                    found.setdefault(row["attack"], []).append((mt["images_per_s"]["mean"], mt[name]["mean"] * scale))
    if not any(series):
        return None
    fig, axes = plt.subplots(1, 2, figsize=(13, 5))
    for ax, (_, _, ylabel, title), found in zip(axes, panels, series):
        for name, pts in sorted(found.items()):
            ax.scatter([p[0] for p in pts], [p[1] for p in pts], label=name, s=18)
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("images / s (log)")
        ax.set_ylabel(ylabel)
        ax.set_title(f"{title}: speed against accuracy (one point per lens)", fontsize=10)
        ax.grid(alpha=0.3)
        if found:
            ax.legend(fontsize=6)
    return _save(fig, path)


def utility_params(variant: str) -> int:
    """Parameter count of the SegFormer variant a profile trains (built offline, random weights)."""
    from benchmark.utility.segformer import build_segformer
    return sum(p.numel() for p in build_segformer(variant).parameters())


def profile_chart(entries: list[dict], path: Path) -> Path | None:
    """Utility and worst-case PSNR of each lens per training profile (smoke vs quick vs paper); the
    x labels name each profile's utility model and its size, which grows with the budget."""
    by_lens: dict[str, dict[str, tuple]] = {}
    models: dict[str, str] = {}
    for e in entries:
        util, worst = metric(e, "utility", "miou"), worst_case(e, "psnr_db", "restorer")
        if util and worst:
            by_lens.setdefault(e["lens"], {})[e["profile"]] = (util[0], worst[0])
            models[e["profile"]] = e["profile_values"]["utility_model"]
    by_lens = {k: v for k, v in by_lens.items() if len(v) > 1}
    if not by_lens:
        return None
    order = [p for p in ("smoke", "quick", "paper") if p in models]
    ticks = [f"{p}\n{models[p]}, {utility_params(models[p]) / 1e6:.2f} M params" for p in order]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for lens, per in sorted(by_lens.items()):
        xs = [order.index(p) for p in order if p in per]
        axes[0].plot(xs, [per[order[x]][0] for x in xs], "o-", label=lens)
        axes[1].plot(xs, [per[order[x]][1] for x in xs], "o-", label=lens)
    axes[0].set_ylabel("mIoU")
    axes[1].set_ylabel("worst-case PSNR dB")
    for ax in axes:
        ax.set_xticks(range(len(order)), ticks, fontsize=8)
        ax.set_xlabel("profile (training budget, utility model)")
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=7)
    return _save(fig, path)


def study_charts(directory: Path, charts: Path) -> list[Path]:
    """Charts of the modelling-choice studies found in `directory`/studies (see benchmark.studies)."""
    from benchmark.charts.studies import psf_grid_figure, utility_size_figure
    written = []
    for name, figure in (("psf_grid", psf_grid_figure), ("utility_size", utility_size_figure)):
        path = directory / "studies" / f"{name}.json"
        if path.is_file():
            written.append(_save(figure(json.loads(path.read_text())), charts / f"{name}.png"))
    return written


def render(directory: Path = LEADERBOARD) -> list[Path]:
    """Write README.md and charts/*.png of the leaderboard in `directory` from its entries."""
    entries = load_entries(directory)
    entries = [e for e in entries if e["lens"] != "sharp"] + [e for e in entries if e["lens"] == "sharp"]
    charts = directory / "charts"
    charts.mkdir(parents=True, exist_ok=True)
    written = [p for p in (
        tradeoff_chart(entries, charts / "utility_vs_psnr.png", "psnr_db", "restorer", "worst-case attacker PSNR dB"),
        tradeoff_chart(entries, charts / "utility_vs_plates.png", "plate_acc", "reader",
                       "worst-case plate accuracy %", 100.0),
        attacker_speed_chart(entries, charts / "attackers_speed_vs_psnr.png"),
        profile_chart(entries, charts / "profiles.png"),
    ) if p is not None] + study_charts(directory, charts)
    text = ["# Leaderboard", "",
            "Rendered by `python -m benchmark report` from `leaderboard/entries/*.json` (written by "
            "`python -m benchmark run ... --publish`); never edited by hand. Mean ± standard deviation over the seeds "
            "listed. Worst case = the strongest attacker of the suite for that lens; W_5% = the plate width below which "
            "the attack-independent bound certifies that no attacker reads more than 5 % of plates. Publishing merges "
            "with a stored entry of the same lens and profile: an attacker row keeps the seeds (listed in the attacker "
            "table) and the provenance of the run that measured it.", "",
            "## Utility against privacy", "", main_table(entries), "",
            *(["## The paper's findings on these entries", "", findings_table(entries), ""]
              if findings_table(entries) else []),
            "## Every attacker", "", attacker_table(entries), "", "## Charts", ""]
    text += [f"![{p.stem}](charts/{p.name})" for p in written]
    pictures = sorted((directory / "samples").glob("*.png")) if (directory / "samples").is_dir() else []
    widths = [p for p in pictures if p.name.startswith("plate_width__")]
    samples = [p for p in pictures if p not in widths]
    if widths:
        text += ["", "## Plate accuracy against plate width (one chart per published run)", ""]
        text += [f"![{p.stem}](samples/{p.name})" for p in widths]
    if samples:
        text += ["", "## Sample images", ""] + [f"![{p.stem}](samples/{p.name})" for p in samples]
    readme = directory / "README.md"
    atomic_write_text(readme, "\n".join(text) + "\n")
    return [readme, *written]


README_START, README_END = "<!-- results:start -->", "<!-- results:end -->"


def update_readme(readme: Path, directory: Path = LEADERBOARD) -> bool:
    """Replace the rendered results table between the markers of the project README (if present)."""
    text = readme.read_text()
    if README_START not in text or README_END not in text:
        return False
    entries = load_entries(directory)
    entries = [e for e in entries if e["lens"] != "sharp"] + [e for e in entries if e["lens"] == "sharp"]
    head, rest = text.split(README_START, 1)
    _, tail = rest.split(README_END, 1)
    atomic_write_text(readme, f"{head}{README_START}\n{main_table(entries)}\n{README_END}{tail}")
    return True
