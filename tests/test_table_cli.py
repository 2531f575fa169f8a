"""`servant table LIBRARY` (issue 39 item 6): it read the library for half a minute with nothing
on the screen, then printed the paper's tables with figures such as `-7223.552` and nothing
saying that these are the paper's method and its equations, not percentages. Now a progress bar
while it reads (on a terminal), and a header naming the method and the units."""

from __future__ import annotations

import contextlib
import io
import json

import pytest

from servant_core.cli import main
from tests.test_cli_boundaries import Terminal
from tests.test_skip_bad import demo_library


@pytest.fixture(scope="module")
def library(tmp_path_factory):
    return demo_library(tmp_path_factory.mktemp("table") / "library")


def table(*argv: str) -> tuple[str, str]:
    out, err = io.StringIO(), Terminal()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        assert main(["table", *argv]) == 0
    return out.getvalue(), err.getvalue()


def test_the_papers_tables_say_their_method_and_units_and_show_progress(library):
    out, err = table(str(library))
    assert "listening to recordings [" in err and "reading pictures [" in err, err
    head = out.splitlines()[0]
    assert "the paper's method" in head.lower(), out
    assert "eq. 1" in head and "eq. 2" in head and "not percentages" in head, out
    assert "Table II: average confidence (mean of eq. 1 and eq. 2)" in out, out


def test_other_methods_tables_say_percent(library):
    out, _ = table(str(library), "--audio-method", "codebook", "--image-method", "bovw")
    head = out.splitlines()[0]
    assert "codebook" in head and "bovw" in head and "the paper's method" not in head.lower(), out
    assert "Table II: average confidence (%)" in out, out


def test_the_tables_json_says_its_units(library):
    out, _ = table(str(library), "--json")
    assert json.loads(out)["confidence_units"] == {"acoustic": "eq. 1", "visual": "eq. 2"}
