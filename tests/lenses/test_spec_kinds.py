"""Every kind of lens spec has a description and a shipped example of that kind, and `list` shows them."""

import pytest

from lenses import load_spec
from lenses.builtin import EXAMPLES
from lenses.spec import KIND_DESCRIPTIONS, KINDS


def test_every_kind_is_described_and_has_an_example():
    assert set(KIND_DESCRIPTIONS) == set(KINDS) == set(EXAMPLES)


@pytest.mark.parametrize("kind", KINDS)
def test_the_example_is_of_its_kind(kind):
    assert load_spec(EXAMPLES[kind]).kind == kind


def test_list_shows_each_kind_with_its_example(capsys):
    from benchmark.cli import main
    assert main(["list"]) == 0
    lines = {line.split()[0]: line for line in capsys.readouterr().out.splitlines() if line.startswith("  ")}
    for kind in KINDS:
        assert EXAMPLES[kind].name in lines[kind]
