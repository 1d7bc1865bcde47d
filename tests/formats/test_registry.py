"""Formats are registered once, by their own module: the source facade imports every module
of formats/logs/, and the order they are tried in is their priorities."""

from __future__ import annotations

import pkgutil

import pytest

import cananalyze.formats.logs as formats_package
from cananalyze.formats import registry, source  # noqa: F401 - importing it registers them


def test_every_format_module_of_the_folder_is_registered():
    modules = {m.name for m in pkgutil.iter_modules(formats_package.__path__)}
    registered = {f.read.__module__.rsplit(".", 1)[-1] for f in registry.FORMATS}
    assert registered <= modules
    assert {"candump", "asc", "blf", "trc", "pcap", "mcap", "gvret", "sevcon"} <= registered
    assert len({f.name for f in registry.FORMATS}) == len(registry.FORMATS)


def test_priorities_are_one_a_format_and_give_the_order():
    priorities = [f.priority for f in registry.FORMATS]
    assert priorities == sorted(priorities) and len(set(priorities)) == len(priorities)
    # CSV dialects: SavvyCAN's before python-can's, as before; text logs: candump first
    names = [f.name for f in registry.FORMATS]
    assert names.index("gvret") < names.index("pycan_csv")
    assert names.index("candump") < names.index("asc") < names.index("trc")


def test_a_second_format_on_a_taken_priority_is_refused():
    taken = registry.FORMATS[0]
    clash = registry.LogFormat(
        "other", "x", lambda head: False, taken.read, priority=taken.priority
    )
    with pytest.raises(ValueError, match="priority"):
        registry.register(clash)
    assert "other" not in [f.name for f in registry.FORMATS]
