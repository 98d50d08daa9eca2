"""docs/parameters.md: its reference is generated from parameter_specs and kept up to date."""

from __future__ import annotations

import pytest

from hexapod_vibration import parameter_specs as specs
from hexapod_vibration.tools import parameter_docs


def test_the_page_is_generated_from_the_specs():
    page = parameter_docs.PAGE.read_text(encoding="utf-8")
    assert parameter_docs.render(page) == page, (
        "docs/parameters.md is stale: run python -m hexapod_vibration.tools.parameter_docs")
    assert parameter_docs.main(["--check"]) == 0


def test_every_parameter_has_its_row_with_range_and_default():
    sections = {s.split("\n", 1)[0]: s for s in parameter_docs.reference().split("### ")[1:]}
    assert list(sections) == list(specs.NODE_SPECS)
    for node, spec in specs.NODE_SPECS.items():
        rows = [line for line in sections[node].splitlines() if line.startswith("| `")]
        assert len(rows) == len(spec.parameters), node
        for parameter, row in zip(spec.parameters, rows, strict=True):
            assert row.startswith(f"| `{parameter.name}`"), row
            assert parameter.range_text().replace("|", "\\|") in row, row
            assert parameter.description.replace("|", "\\|") in row, row
            assert (" (ro) |" in row) == parameter.read_only, row


def test_a_stale_or_unmarked_page_is_found():
    page = parameter_docs.PAGE.read_text(encoding="utf-8")
    stale = page.replace("| `mu` |", "| `mu_old` |")
    assert stale != page and parameter_docs.render(stale) == page
    with pytest.raises(ValueError, match="no"):
        parameter_docs.render("# Parameters\n")
    assert parameter_docs.main(["--write", "x"]) == 2
