"""The README as a new user reads it: its Quick start gives each command's measured time (every time
in it one docs/costs.md measured), and no commit hash or issue number, which mean nothing to a reader."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
COSTS = (ROOT / "docs" / "costs.md").read_text()
TIME = re.compile(r"\b\d+ min \d+ s\b|\b\d+-\d+ s\b|\b\d+ min \d+ s\b|\b\d+:\d\d\b")


def quick_start() -> str:
    start = README.index("## Quick start")
    return README[start:README.index("\n## ", start + 1)]


def test_every_time_in_the_quick_start_is_measured_in_docs_costs_md():
    times = TIME.findall(quick_start())
    assert len(times) >= 6
    for t in times:
        assert t in COSTS or t.replace(" min ", ":").replace(" s", "") in COSTS, t


def test_each_quick_start_command_has_its_time_beside_it():
    steps = re.split(r"\n\d\. ", quick_start())[1:]
    assert len(steps) == 4 and "--profile smoke" in steps[1] and "run --lens gp" in steps[2]
    for step in steps:
        assert TIME.search(step.split("\n\n")[0]), step[:80]
    assert "download.pytorch.org/whl/cpu" in steps[0] and "GB" in steps[0]


def test_no_commit_hash_or_issue_number_in_the_readme():
    text = README.split("<!-- results:start -->")[0] + README.split("<!-- results:end -->")[-1]
    assert not re.findall(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b", text)
    assert not re.findall(r"\bissues? \d+|#\d+\b", text, flags=re.IGNORECASE)


def test_the_glossary_explains_the_words_the_tables_use():
    for word in ("**utility**", "**worst case**", "**ceiling**", "**Fano**", "**W_5%**", "**T**"):
        assert word in quick_start()
