"""Run charts legible at page width: each run chart rendered with a crowded case (20 chains,
5 lenses; 12 restorers) keeps its legends, labels and notes off the data and off each other, uses fonts
readable at ~1000 px, draws at most MAX_CHAINS lines per panel with colours that never repeat within
a panel and error bars from the data; the sample grid shows each image's own scores; the plate
gallery's reads sit under their crops, never over the column titles; the same data render
byte-identical PNGs."""

from __future__ import annotations

import matplotlib.colors
import numpy as np
import pytest
import torch
from matplotlib.collections import PolyCollection
from matplotlib.container import ErrorbarContainer

from attacks import PlateRead
from benchmark.results.charts import plate_gallery, plate_width, restorers, samples
from benchmark.results.charts import bound_chart as bound
from benchmark.results.metrics import psnr, ssim
from benchmark.results.plate_scoring import readable
from benchmark.results.schema import Row
from benchmark.results.stats import wilson_interval
from benchmark.scenes import load_scenes
from chart_layout import assert_legible_layout, rendered_labels  # tests/chart_layout.py

LENSES = ["sharp", "gp", "ideal", "defocus", "a-lens-with-a-rather-long-name"]
READERS = ["lpdr", "lpdr-oracle", "easyocr", "plate-cnn"]
CHAINS = READERS + [f"{r}>{d}" for r in ("raw", "wiener-known-psf", "nafnet-known-pairs", "nafnet-generic")
                    for d in READERS]  # 20 chains
MIN_FONT_PT = 8.0


def crowded_plates(seed: int = 0) -> list[dict]:
    rng = np.random.default_rng(seed)
    records = []
    for lens in LENSES:
        for chain in CHAINS:
            strength = rng.uniform()
            for width in rng.uniform(30, 260, 30):
                records.append({"lens": lens, "attack": chain, "width_px": float(width),
                                "correct": bool(rng.uniform() < strength * min(1.0, width / 150))})
    return records


def crowded_ceilings() -> dict:
    return {lens: (np.array([2.0, 4, 8, 16, 32, 64, 128, 256]), np.array([0.02, 0.3, 1, 1, 1, 1, 1, 1]))
            for lens in LENSES}


def test_plate_width_crowded_panels_are_legible_grouped_and_carry_wilson_error_bars():
    records = crowded_plates()
    fig = plate_width.plate_width_figure(records, ceilings=crowded_ceilings())
    assert_legible_layout(fig, MIN_FONT_PT)
    panels = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title(loc="left") for ax in panels] == [f"lens: {n}" for n in
                                                          ["sharp", "a-lens-with-a-rather-long-name", "defocus", "gp", "ideal"]]
    curves = plate_width.width_accuracy(records)
    for ax in panels:
        lens = ax.get_title(loc="left").removeprefix("lens: ")
        bars = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
        assert len(bars) == plate_width.MAX_CHAINS - 1  # the strongest five drawn ...
        assert any(isinstance(c, PolyCollection) for c in ax.collections)  # ... the rest one grey range
        assert any("15 other chains" in t.get_text() for t in ax.get_legend().get_texts())
        colours = [matplotlib.colors.to_hex(c.lines[0].get_color()) for c in bars]
        assert len(set(colours)) == len(colours) and "#7f7f7f" not in colours  # no repeat, no band grey
        shown, grouped = plate_width.panel_chains(curves, lens)
        assert len(shown) == 5 and len(grouped) == 15
        strength = {a: plate_width.chain_strength(*curves[(lens, a)][1:]) for a in shown + grouped}
        assert min(strength[a] for a in shown) >= max(strength[a] for a in grouped)
        # The error bars are each bin's Wilson 95 % interval.
        _, acc, counts = curves[(lens, shown[0])]
        keep = counts > 0
        segments = bars[0].lines[2][0].get_segments()
        expected = [wilson_interval(int(round(a * n)), int(n)) for a, n in zip(acc[keep], counts[keep])]
        np.testing.assert_allclose([(s[0][1], s[1][1]) for s in segments], expected, atol=1e-9)


def test_plate_width_few_chains_draws_them_all():
    records = [r for r in crowded_plates() if r["attack"] in READERS[:3] and r["lens"] in ("sharp", "gp")]
    fig = plate_width.plate_width_figure(records)
    assert_legible_layout(fig, MIN_FONT_PT)
    for ax in fig.axes:
        assert len(ax.containers) == 3
        assert not any("other chains" in t.get_text() for t in ax.get_legend().get_texts())


def restorer_rows() -> list[Row]:
    rows = []
    names = [f"restorer-{i:02d}" for i in range(12)]
    for lens in LENSES[1:]:
        for k, name in enumerate(names):
            for seed in (0, 1):
                value = 15.0 + k + seed * 0.5
                row = Row(kind="restorer", lens=lens, attack=name, seed=seed, profile="smoke", scenes="synthetic",
                          metrics={"psnr_db": value, "ssim": 0.5, "images_per_s": 1.0 + k, "n_images": 4.0},
                          threat_model="known-pairs", restorer=name)
                row.set_interval("psnr_db", value - 1.0, value + 1.0, "bootstrap")
                rows.append(row)
    return rows


def test_restorer_chart_crowded_is_legible_with_distinct_colours_and_interval_bars():
    rows = restorer_rows()
    fig = restorers.restorer_speed_figure(rows)
    assert_legible_layout(fig, MIN_FONT_PT)
    (ax,) = fig.axes
    handles = ax.get_legend().legend_handles
    restorer_colours = [matplotlib.colors.to_hex(h.get_color()) for h in handles[:12]]
    lens_colours = {matplotlib.colors.to_hex(h.get_color()) for h in handles[12:]}
    assert len(set(restorer_colours)) == 12 and lens_colours == {"#000000"}
    assert not set(restorer_colours) & {"#7f7f7f", "#c7c7c7", "#808080", "#000000"}  # no restorer in grey
    assert len(ax.containers) == 4 * 12  # one point with an error bar per (lens, restorer)
    # Two seeds: the bar spans both seeds' intervals (15 - 1 .. 15.5 + 1 for restorer-00).
    spans = sorted((s[0][1], s[1][1]) for c in ax.containers for s in c.lines[2][0].get_segments())
    assert spans[0] == pytest.approx((14.0, 16.5))


def test_bound_chart_shows_where_the_ceiling_rises_with_a_readable_note():
    fig = bound.bound_figure(crowded_ceilings())
    assert_legible_layout(fig, MIN_FONT_PT)
    (ax,) = fig.axes
    lo, hi = ax.get_xlim()
    assert lo < 2 and 16 <= hi < 32  # ends one octave past 8 px, where every ceiling is 1
    assert any("From 8 px on the ceiling is 1 for every lens" in t.get_text().replace("\n", " ") for t in fig.texts)
    assert bound.saturation_width({"x": (np.array([4, 8]), np.array([0.1, 0.5]))}) is None


def test_sample_grid_scores_each_image_shown():
    rng = np.random.default_rng(1)
    scene = rng.uniform(size=(64, 128, 3)).astype(np.float32)
    sensor = np.clip(scene + rng.normal(0, 0.2, scene.shape), 0, 1).astype(np.float32)
    restored = {f"restorer-{k}": np.clip(scene + rng.normal(0, 0.02 * (k + 1), scene.shape), 0, 1).astype(np.float32)
                for k in range(5)}
    fig = samples.sample_grid_figure("gp", np.ones((3, 9, 9)), scene, sensor, restored)
    assert_legible_layout(fig, MIN_FONT_PT)
    titles = {ax.get_title().split("\n")[0]: ax.get_title() for ax in fig.axes if ax.get_title()}

    def scores(img):
        x, ref = (torch.from_numpy(a).permute(2, 0, 1)[None] for a in (img, scene))
        return float(psnr(x, ref)[0]), float(ssim(x, ref)[0])

    for name, img in {"sensor": sensor, **restored}.items():
        db, s = scores(img)
        assert titles[name].endswith(f"PSNR {db:.2f} dB, SSIM {s:.3f}"), titles[name]
    assert len({t.split("\n")[1] for n, t in titles.items() if n.startswith("restorer")}) == 5  # each its own


@pytest.mark.slow
def test_plate_gallery_reads_sit_under_crops_and_a_caption_explains_them():
    """Eight sources (sharp, sensor, six restorers): two blocks of at most MAX_COLUMNS, each titled."""
    scenes = load_scenes("synthetic", "val", 4, (512, 1024), 0)
    sharp = torch.from_numpy(np.stack([s.image for s in scenes])).permute(0, 3, 1, 2)
    plates = [(i, p) for i, s in enumerate(scenes) for p in s.plates if readable(p)]
    restorer_names = ["wiener-known-psf", "nafnet-known-pairs", "richardson-lucy-known-psf", "r4", "r5", "r6"]
    reads = {name: [[PlateRead(p.text if k % 2 else "WRONG12", tuple(map(float, p.box_xyxy)), 0.9)
                     for k, p in enumerate(s.plates)] for s in scenes] for name in ["sensor"] + restorer_names}
    images = {"sharp": sharp, "sensor": sharp * 0.5, **{n: sharp.flip(-1) for n in restorer_names}}
    fig = plate_gallery.plate_gallery_figure(images, scenes, reads, max_plates=6, reader="lpdr-oracle")
    assert_legible_layout(fig, MIN_FONT_PT)
    assert fig.get_size_inches()[0] * plate_gallery.DPI <= 1200
    _, renderer = rendered_labels(fig)
    columns = [ax for ax in fig.axes if ax.get_title()]
    assert sorted(ax.get_title() for ax in columns) == sorted(images)
    assert len({round(ax.get_position().y1, 3) for ax in columns}) == 2  # two blocks, each with its titles
    reads_shown = [(ax, ax.xaxis.label) for ax in fig.axes if ax.xaxis.label.get_text()]
    assert len(reads_shown) == 7 * min(6, len(plates))
    assert {r.get_color() for _, r in reads_shown} == {"green", "red"}
    for ax, read in reads_shown:  # under its crop, and over no column title
        box = read.get_window_extent(renderer)
        assert box.y1 <= ax.get_window_extent().y0 + 1
        assert not any(box.overlaps(col.title.get_window_extent(renderer)) for col in columns)
    caption = " ".join(t.get_text().replace("\n", " ") for t in fig.texts)
    assert "lpdr-oracle read there" in caption and "green" in caption and "red" in caption


@pytest.mark.parametrize("chart", ["plate_width", "restorers", "bound"])
def test_same_data_render_byte_identical_pngs(tmp_path, chart):
    def write(path):
        if chart == "plate_width":
            return plate_width.write_plate_width_chart(crowded_plates(), path, ceilings=crowded_ceilings())
        if chart == "restorers":
            return restorers.write_restorer_speed_chart(restorer_rows(), path)
        return bound.write_bound_chart(crowded_ceilings(), path)
    assert write(tmp_path / "a.png").read_bytes() == write(tmp_path / "b.png").read_bytes()


@pytest.mark.slow
def test_ideal_observer_chart_of_the_published_leaderboard_is_legible_at_page_width(tmp_path):
    """The leaderboard's own study and entries (12 lenses, up to 24 readers and chains a lens): lens
    panels three to a row, each legend under its panel and at most MAX_READERS readers in colour."""
    import json
    from pathlib import Path

    from benchmark.results.charts import ideal_observer_chart as ideal_observer
    from benchmark.results.entries import load_entries
    board = Path(__file__).resolve().parents[3] / "leaderboard"
    study = json.loads((board / "studies" / "ideal_observer.json").read_text())
    readers = json.loads((board / "studies" / "ideal_observer_readers.json").read_text())
    entries = load_entries(board)
    fig = ideal_observer.ideal_observer_figure(study, entries, readers)
    assert_legible_layout(fig, MIN_FONT_PT)
    assert fig.get_size_inches()[0] * ideal_observer.DPI <= 1200  # shown ~1000 px wide, fonts stay >= 8 pt x 0.83
    panels = [ax for ax in fig.axes if ax.get_title() in study["lenses"]]
    assert len(panels) == len(study["lenses"]) >= 10
    assert len({round(ax.get_position().x0, 3) for ax in panels}) == 3  # three columns
    for ax in panels:
        coloured = [c for c in ax.containers if matplotlib.colors.to_hex(c.lines[0].get_color()) != "#8c8c8c"
                    and c.lines[0].get_marker() == "o"]
        assert len(coloured) <= ideal_observer.MAX_READERS
        colours = [matplotlib.colors.to_hex(c.lines[0].get_color()) for c in coloured]
        assert len(set(colours)) == len(colours)
