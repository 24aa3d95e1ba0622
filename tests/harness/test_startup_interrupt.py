"""A Ctrl-C (or SIGTERM) while the ``contactbench`` command is still loading its modules or
reading its arguments ends it in one line, exit 130 (143), as one later does -- not in a
traceback through the imports (``contactbench.command``, ``harness.cli.main``); and a stop
that an import swallowed still stops the command (``stops.raise_noted``)."""

from __future__ import annotations

import signal
import sys
import types
from pathlib import Path

import pytest

from contactbench import command
from contactbench.plugins import PluginRegistry
from contactbench.harness import cli


def test_a_ctrl_c_while_the_command_loads_its_modules_is_one_line(monkeypatch: pytest.MonkeyPatch,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    loading = types.ModuleType("contactbench.harness.cli")

    def interrupted(name: str) -> object:
        raise KeyboardInterrupt

    loading.__getattr__ = interrupted  # type: ignore[method-assign]
    monkeypatch.setitem(sys.modules, "contactbench.harness.cli", loading)
    assert command.main() == 130
    assert capsys.readouterr().err == "interrupted: contactbench was starting; nothing was run\n"


@pytest.mark.parametrize("stop, code, word", [(KeyboardInterrupt, 130, "interrupted"),
                                              (cli.Terminated, 143, "terminated")])
def test_a_stop_while_the_arguments_are_read_is_one_line(monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture[str], stop: type,
                                                         code: int, word: str) -> None:
    def build_parser() -> object:
        raise stop()

    monkeypatch.setattr(cli, "build_parser", build_parser)
    assert cli.main(["list", "scenes"]) == code
    assert capsys.readouterr().err == f"{word}: contactbench was starting; nothing was run\n"


def test_the_installed_command_is_the_quiet_entry_point() -> None:
    from importlib import metadata

    (entry,) = [e for e in metadata.entry_points(group="console_scripts") if e.name == "contactbench"]
    assert entry.value == "contactbench.command:main"


SWALLOWS_A_STOP = '''
import os, signal, time
try:  # (as a third-party import can: a KeyboardInterrupt caught where it landed)
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(2)
except KeyboardInterrupt:
    pass
'''


def test_a_stop_an_import_swallowed_still_stops_the_discovery(tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    package = tmp_path / "cb_swallowing_plugins"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "swallows.py").write_text(SWALLOWS_A_STOP)
    monkeypatch.syspath_prepend(str(tmp_path))
    before = signal.signal(signal.SIGINT, signal.default_int_handler)  # (a test worker may ignore SIGINT)
    try:
        registry: PluginRegistry[object] = PluginRegistry("thing", package="cb_swallowing_plugins")
        with pytest.raises(KeyboardInterrupt):
            registry.discover()
    finally:
        signal.signal(signal.SIGINT, before)
        sys.modules.pop("cb_swallowing_plugins.swallows", None)
        sys.modules.pop("cb_swallowing_plugins", None)
