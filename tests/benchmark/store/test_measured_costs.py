"""The shipped table of measured costs (benchmark.store.measured_costs): every figure in it is one of
docs/costs.md's, an empty-cache dry run totals them and names the machine, and the profiles'
descriptions say what docs/costs.md measured."""

import json
import re
from pathlib import Path

import pytest

import benchmark
from benchmark.store import measured_costs
from benchmark.store.profiles import PROFILES

DOCS = (Path(__file__).resolve().parents[3] / "docs" / "costs.md").read_text()


def _docs_text(seconds: float) -> str:
    m, s = divmod(int(seconds), 60)
    return f"{m} min {s} s" if m else f"{s} s"


def test_every_figure_of_the_table_is_in_docs_costs_md():
    table = measured_costs.table()["profiles"]
    figures = 0
    for profile in table.values():
        for task in profile["tasks"]:
            assert f"| {task['seconds']} s |" in DOCS or f" {task['seconds']} s" in DOCS, task
            figures += 1
        for run in profile["runs"]:
            text = "-".join(str(s) for s in run["seconds"]) + " s" if len(run["seconds"]) > 1 \
                else _docs_text(run["seconds"][0])
            assert text in DOCS, run
            if run["date"]:
                assert run["date"] in DOCS
        where = profile.get("tasks_measured_on")
        if where:
            assert where["date"] in DOCS
    assert figures >= 10


def test_an_empty_cache_dry_run_gives_a_total_and_the_machine(tmp_path, monkeypatch):
    monkeypatch.setenv("PLB_CACHE", str(tmp_path))
    quick = measured_costs.table()["profiles"]["quick"]
    plan = benchmark.plan(lenses=["gp"], profile="quick")  # the standard ensemble, as the table's evaluations
    todo = [t for t in plan.tasks if not t.cached]
    assert len(todo) == len(plan.tasks) > 6
    # What the table says for this plan: per task kind (a co-designed lens), the light fits once, the
    # shipped lens and the clean net installed.
    figures = {(t["kind"], t.get("restorer"), t.get("lens")): t["seconds"] for t in quick["tasks"]
               if t.get("attackers", "standard") == "standard"}
    expected = sum(figures[k] for k in [("sharp", None, None), ("spectrum", None, None), ("bound", None, None),
                                        ("utility", None, "co-designed"), ("evaluate", None, "co-designed"),
                                        ("fit", "*", None), ("fit", "nafnet-known-psf-tuned", "co-designed")])
    installed = {t.key for t in todo if t.estimate.installed}
    # The shipped lens, the clean net and, at seed 0, the generic NAFNet's weights are installed, not fitted.
    assert installed == {"clean-utility_s0", "lens_s0_gp", "fit_s0_gp_nafnet-generic"}
    summary = plan.render().splitlines()[-1]
    match = re.search(r"estimated total (\d+) s \(([\d.]+) min\) for (\d+) of them", summary)
    assert match, summary
    assert int(match[1]) == expected and int(match[3]) == len(todo) - len(installed)
    assert quick["tasks_measured_on"]["machine"] in summary and quick["tasks_measured_on"]["date"] in summary
    assert "unknown" not in summary
    # Another seed co-designs (a figure of its own day, named in the summary): every task quoted.
    other = benchmark.plan(lenses=["gp", "defocus"], profile="quick", seeds=[1])
    total = benchmark.api.task_costs.total([(t.seed, t.lens, t.estimate) for t in other.tasks])
    per_lens = {kind: sum(figures[(k, None, kind)] for k in ("lens", "utility", "evaluate")) + figures[("fit", "*", None)]
                + figures[("fit", "nafnet-known-psf-tuned", kind)] for kind in ("fixed", "co-designed")}
    # the generic NAFNet's fit (shipped only for seed 0) once per seed, shared by the lenses
    shared = figures[("sharp", None, None)] + figures[("spectrum", None, None)] + figures[("fit", "nafnet-generic", None)]
    assert total.seconds == pytest.approx(shared + 2 * figures[("bound", None, None)] + sum(per_lens.values()))
    assert (total.unknown, total.installed) == (0, 1)  # the clean net ships for every seed
    codesign = next(t for t in quick["tasks"] if t["kind"] == "lens" and t["lens"] == "co-designed")
    assert codesign["date"] in other.render().splitlines()[-1]
    # The default run is quoted its evaluation figure; the cross product, measured with other attackers, is not.
    standard = {t.get("lens"): t["seconds"] for t in quick["tasks"] if t.get("attackers") == "standard"}
    quoted = {t.lens: t.estimate.seconds for t in other.tasks if t.kind == "evaluate"}
    assert quoted == {"gp": standard["co-designed"], "defocus": standard["fixed"]}
    cross = benchmark.plan(lenses=["defocus"], profile="quick", seeds=[1], all_chains=True)
    assert [t.estimate.seconds for t in cross.tasks if t.kind == "evaluate"] == [None]
    named = benchmark.plan(lenses=["defocus"], attacks=["identity", "lpdr"], profile="quick", seeds=[1])
    assert [t.estimate.seconds for t in named.tasks if t.kind == "evaluate"] == [None]  # measured for neither set


def test_a_profile_that_differs_from_the_shipped_one_is_not_quoted(tmp_path, monkeypatch):
    import dataclasses
    monkeypatch.setenv("PLB_CACHE", str(tmp_path))
    changed = dataclasses.replace(PROFILES["quick"], n_val=32)
    plan = benchmark.plan(lenses=["defocus"], profile=changed)
    assert all(t.estimate.seconds is None for t in plan.tasks)


def test_profile_descriptions_say_what_was_measured():
    table = measured_costs.table()["profiles"]
    for name, profile in PROFILES.items():
        runs = table.get(name, {}).get("runs", [])
        if runs:
            assert measured_costs.run_text(name) in profile.description
            first = runs[0]["seconds"]
            assert " to ".join(measured_costs._minutes(s) for s in first) in profile.description
        assert "under" not in profile.description  # no typed-in promise
        assert "description" not in profile.to_dict()
    assert json.loads(measured_costs.TABLE.read_text()) == measured_costs.table()
