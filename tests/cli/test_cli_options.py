"""Every flag of every sub-command comes from the one registry (cli/options.py), and the
built-in devices the CLI names are the ones found in decoders/."""

from __future__ import annotations

import argparse
import ast
import shutil
from pathlib import Path

import pytest

from cananalyze.cli import options
from cananalyze.cli.main import build_parser, main
from cananalyze.devices import builtin, catalog

CLI = Path(options.__file__).parent


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    raise AssertionError("no sub-commands")


def _registry_entry(action: argparse.Action) -> str | None:
    """The registry key whose spelling, destination and help this parsed action has."""
    names = tuple(action.option_strings) or (action.dest,)
    for key, flag in options.FLAGS.items():
        help_text = flag.kwargs.get("help")
        if callable(help_text):
            help_text = help_text()
        same_names = names[len(names) - len(flag.names) :] == flag.names
        if same_names and (help_text is None or help_text == action.help):
            return key
    return None


def test_every_subcommand_flag_comes_from_the_registry():
    parser = build_parser()
    subs = _subparsers(parser)
    assert {"decode", "check", "report", "export", "live", "fleet", "query", "devices"} <= set(subs)
    seen = set()
    for name, sub in [("cananalyze", parser), *subs.items()]:
        for action in sub._actions:
            if isinstance(action, argparse._HelpAction | argparse._SubParsersAction):
                continue
            key = _registry_entry(action)
            assert key is not None, (
                f"{name}: {action.option_strings or action.dest} not from the registry"
            )
            seen.add(key)
    assert seen == set(options.FLAGS), (
        f"registry entries no command takes: {set(options.FLAGS) - seen}"
    )


def test_no_cli_module_declares_a_flag_itself():
    """add_argument is called in options.py only: a flag's default and help live there."""
    for path in sorted(CLI.glob("*.py")):
        if path.name == "options.py":
            continue
        calls = [
            node.lineno
            for node in ast.walk(ast.parse(path.read_text()))
            if isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "add_argument"
        ]
        assert not calls, f"{path.name} declares flags at lines {calls}"


def test_shared_flags_are_the_same_in_every_command():
    """--rules, --bitrate, --quiet, --sdo-timeout, --network: one default and help everywhere."""
    subs = _subparsers(build_parser())
    for flag in ("--rules", "--bitrate", "--quiet", "--sdo-timeout", "--network", "--device"):
        found = {
            (repr(a.default), a.help)
            for sub in subs.values()
            for a in sub._actions
            if flag in a.option_strings
        }
        assert len(found) == 1, (flag, found)
    timeout = next(
        a for a in subs["decode"]._actions if "--sdo-timeout" in a.option_strings
    ).default
    from cananalyze.pipeline.options import Options

    assert timeout == Options().sdo_timeout == 1.0


def test_every_command_that_reads_a_dbc_but_writes_none_takes_dbc_too():
    """--dbc-in everywhere; --dbc as its other name except in export, where --dbc writes one."""
    for name, sub in _subparsers(build_parser()).items():
        dbc = [a for a in sub._actions if a.dest == "dbc_in"]
        if not dbc:
            continue
        want = ["--dbc-in"] if name == "export" else ["--dbc", "--dbc-in"]
        assert dbc[0].option_strings == want, name
        if name != "export":
            assert sub.parse_args(["--dbc", "x.dbc", *_required(name)]).dbc_in == ["x.dbc"]


def test_report_needs_its_output_file(capsys):
    """-o is optional where stdout is the default (decode), required where there is none."""
    with pytest.raises(SystemExit) as exit_:
        main(["report", "log.log"])
    assert exit_.value.code == 2
    assert "-o/--output" in capsys.readouterr().err
    with pytest.raises(ValueError, match="output"):
        options.add(argparse.ArgumentParser(), "title", required=("output",))


def _required(name: str) -> list[str]:
    required = {
        "fleet": ["log.log", "--out", "ds"],
        "live": [],
        "report": ["log.log", "-o", "r.html"],
        "diff": ["a.log", "b.log"],
    }
    return required.get(name, ["log.log"])


@pytest.fixture
def one_more_device(tmp_path, monkeypatch):
    """decoders/ copied with one more device: dat7014's EDS and sidecar as `mydevice`."""
    src = catalog.decoders_dir()
    folder = tmp_path / "decoders"
    shutil.copytree(src, folder)
    shutil.copy(src / "dat7014.eds", folder / "mydevice.eds")
    sidecar = (src / "dat7014.toml").read_text().replace('key = "dat7014"', 'key = "mydevice"')
    (folder / "mydevice.toml").write_text(sidecar)
    monkeypatch.setattr(catalog, "decoders_dir", lambda: folder)
    catalog.builtin_keys.cache_clear()
    builtin.load_builtin.cache_clear()
    yield "mydevice"
    catalog.builtin_keys.cache_clear()
    builtin.load_builtin.cache_clear()


def test_a_device_is_its_eds_and_sidecar_and_nothing_else(one_more_device, capsys):
    assert one_more_device in catalog.builtin_keys()
    assert main(["devices"]) == 0
    listed = [line.split()[0] for line in capsys.readouterr().out.splitlines()[1:] if line]
    assert one_more_device in listed
    help_text = _subparsers(build_parser())["decode"].format_help()
    assert one_more_device in " ".join(help_text.split())
    assert main(["devices", one_more_device]) == 0
    assert "Datexel" in capsys.readouterr().out


def test_without_the_sidecar_an_eds_is_no_builtin(tmp_path, monkeypatch):
    folder = tmp_path / "decoders"
    folder.mkdir()
    shutil.copy(catalog.decoders_dir() / "dat7014.eds", folder / "lonely.eds")
    monkeypatch.setattr(catalog, "decoders_dir", lambda: folder)
    catalog.builtin_keys.cache_clear()
    try:
        assert catalog.builtin_keys() == ()
    finally:
        catalog.builtin_keys.cache_clear()
