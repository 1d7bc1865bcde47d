"""LazyNotes reads and writes like the dict it stands for; the fill runs once, first."""

from __future__ import annotations

import copy
import json
import pickle

from cananalyze.decode.sdo.lazynotes import LazyNotes


def _make():
    calls = []

    def fill(d):
        calls.append(1)
        LazyNotes.write(d, 1, {"role": "upload request 0x1018:01"})
        LazyNotes.write(d, 2, {"role": "late"})

    return LazyNotes({2: {"signals": {"a": 1}}}, fill), calls


def test_every_access_sees_the_pending_notes_once() -> None:
    for access in (
        lambda n: n[1],
        lambda n: n.get(1),
        lambda n: 1 in n,
        lambda n: len(n),
        lambda n: list(n),
        lambda n: dict(n),
        lambda n: {**n},
        lambda n: n.items(),
        lambda n: json.dumps(n),
        lambda n: copy.deepcopy(n),
        lambda n: pickle.loads(pickle.dumps(n)),
    ):
        notes, calls = _make()
        assert calls == []
        access(notes)
        assert calls == [1]
        assert dict(notes) == {
            1: {"role": "upload request 0x1018:01"},
            2: {"signals": {"a": 1}, "role": "late"},
        }
        assert calls == [1]


def test_later_writers_merge_after_the_pending_note() -> None:
    notes, _ = _make()
    notes.setdefault(1, {}).update({"role": "override", "x": 1})
    notes[3] = {"y": 2}
    assert notes[1] == {"role": "override", "x": 1} and notes[3] == {"y": 2} and len(notes) == 3


def test_deferred_fills_run_in_order() -> None:
    notes, _ = _make()
    notes.defer(lambda d: LazyNotes.write(d, 1, {"role": "second"}))
    assert notes[1]["role"] == "second"
