"""Charts of the modelling-choice studies (``leaderboard/studies/*.json``)."""

from __future__ import annotations

import matplotlib.ticker
from matplotlib.figure import Figure

from benchmark.results.charts import new_figure

KNOB_TITLES = {"energy_fraction": "PSF support K (energy fraction held)", "pupil_samples": "pupil grid N",
               "oversample": "pixel integration: s x s midpoints (0 = exact)"}


def psf_grid_figure(study: dict) -> Figure:
    """One panel per knob: image PSNR against the reference model vs PSF+gradient time, one line per lens,
    the suite's default circled."""
    knobs = list(dict.fromkeys(r["knob"] for r in study["records"]))
    fig = new_figure(figsize=(5 * len(knobs), 4.2))
    axes = fig.subplots(1, len(knobs), sharey=True, squeeze=False)[0]
    for ax, knob in zip(axes, knobs):
        records = [r for r in study["records"] if r["knob"] == knob]
        for lens in dict.fromkeys(r["lens"] for r in records):
            pts = sorted((r for r in records if r["lens"] == lens), key=lambda r: r["value"])
            line, = ax.plot([r["psf_grad_ms"] for r in pts], [r["image_psnr_db"] for r in pts], "o-", ms=4, label=lens)
            for r in pts:
                ax.annotate(f"{r['value']:g}", (r["psf_grad_ms"], r["image_psnr_db"]), textcoords="offset points",
                            xytext=(3, 3), fontsize=7, color=line.get_color())
                if r["default"]:
                    ax.plot(r["psf_grad_ms"], r["image_psnr_db"], "o", ms=11, mfc="none", color=line.get_color())
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_title(KNOB_TITLES.get(knob, knob), fontsize=10)
        ax.set_xlabel("PSF + gradient ms, 1 thread (log; fastest of repeats)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("scene PSNR dB vs reference optics (higher = closer)")
    axes[-1].legend(fontsize=7, title="circled: suite default", title_fontsize=7)
    return fig


def utility_size_figure(study: dict) -> Figure:
    """Three panels, one point (or line) per SegFormer variant, each trained to its plateau: mIoU against
    parameters and against training seconds (95 % scene-bootstrap intervals as error bars, where the
    study has them), and the learning curves."""
    records = sorted(study["records"], key=lambda r: r["params"])
    fig = new_figure(figsize=(15, 4.4))
    by_params, by_time, curves = fig.subplots(1, 3)

    def errors(r: dict) -> list[list[float]]:
        low, high = r.get("intervals", {}).get("miou", (r["miou"], r["miou"]))
        return [[r["miou"] - low], [high - r["miou"]]]

    for r in records:
        label = r["variant"]
        by_params.errorbar(r["params"] / 1e6, r["miou"], yerr=errors(r), fmt="o", capsize=3, label=label)
        by_params.annotate(f"{label}\n{r['images_per_s']:.1f} img/s", (r["params"] / 1e6, r["miou"]),
                           textcoords="offset points", xytext=(5, -14), fontsize=8)
        by_time.errorbar(r["train_s"] / 60, r["miou"], yerr=errors(r), fmt="o", capsize=3, label=label)
        by_time.annotate(label, (r["train_s"] / 60, r["miou"]), textcoords="offset points", xytext=(5, -10),
                         fontsize=8)
        if r.get("curve"):
            plateau = r.get("plateau", {})
            mark = "plateau" if plateau.get("reached") else "no plateau"
            curves.plot([c["step"] for c in r["curve"]], [c["miou"] for c in r["curve"]], "o-", ms=3,
                        label=f"{label} ({mark})")
    for ax in (by_params, by_time):
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_ylabel("mIoU on sharp val scenes (95 % CI)")
        ax.grid(alpha=0.3)
    by_params.set_xlabel("parameters (millions, log)")
    threads = sorted({r.get("train_threads") for r in records if r.get("train_threads")})
    by_time.set_xlabel(f"training minutes (log; {','.join(map(str, threads)) or '?'} thread(s), load in the JSON)")
    curves.set_xlabel("training step")
    curves.set_ylabel("mIoU on the curve's val scenes")
    curves.grid(alpha=0.3)
    if any(r.get("curve") for r in records):
        curves.legend(fontsize=8)
    profile = study.get("profile", {})
    fig.suptitle(f"Utility model size, each trained to its plateau ({profile.get('name', '?')}: "
                 f"{profile.get('pretrain_steps', '?')} steps, {profile.get('n_val', '?')} val scenes, "
                 f"seed {study.get('seed', '?')})", fontsize=10)
    return fig
