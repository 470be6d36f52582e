"""Ctrl-C and SIGTERM are never lost: not inside CasADi's bindings, not inside class creation, not at exit.

Each test sends the process a real SIGTERM at a place where a plain ``raise KeyboardInterrupt`` handler loses
it (CasADi's argument conversion turns the exception into ``NotImplementedError`` or swallows it; Python
wraps one raised in ``__set_name__`` in ``RuntimeError``; one passing through ``exec``'d code makes CPython
end by SIGINT), and checks that the command still ends with status 130 and its one-line message.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import casadi as ca
import pytest

from mobisense import cli
from mobisense.core import commands, interrupts


def _run_as_validate(monkeypatch: pytest.MonkeyPatch, body) -> int:
    monkeypatch.setattr(commands.ValidateCommand, "run", staticmethod(lambda args: body() or 0))
    return cli.main(["validate", "unused.yaml"])


class _Signalling(ca.Callback):
    """A CasADi function (x ↦ 2x) whose evaluation receives SIGTERM: the handler runs below CasADi's C++."""

    def __init__(self) -> None:
        ca.Callback.__init__(self)
        self.construct("signalling", {})

    def eval(self, arg):
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):  # the handler runs between bytecodes: here
            pass
        return [2 * arg[0]]


def test_a_signal_inside_casadi_is_recorded_and_stops_the_command_at_the_end(monkeypatch, capsys):
    results = []
    code = _run_as_validate(monkeypatch, lambda: results.append(float(_Signalling()(3.0))))
    assert results == [6.0]  # CasADi finished its call: nothing was raised inside it
    assert code == 130
    assert capsys.readouterr().err.strip() == "mobisense: interrupted; files already written are complete"
    assert not interrupts.interrupt_received()  # the record is cleared once acted on


def test_the_error_an_interrupt_causes_is_reported_as_the_interrupt(monkeypatch, capsys):
    class Announcing:
        def __set_name__(self, owner, name):  # Python 3.11 wraps what this raises in RuntimeError
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):  # the handler runs between bytecodes: here
                pass

    def create_a_class():
        type("Owner", (), {"field": Announcing()})

    assert _run_as_validate(monkeypatch, create_a_class) == 130
    assert "interrupted" in capsys.readouterr().err


def test_outside_casadi_the_handler_raises_at_once():
    previous = signal.signal(signal.SIGTERM, interrupts.interrupt_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):
                pass
        assert interrupts.interrupt_received()
    finally:
        signal.signal(signal.SIGTERM, previous)
        interrupts.forget_interrupts()


def test_a_held_signal_is_raised_after_the_block_then_forgotten():
    with pytest.raises(KeyboardInterrupt), interrupts.deferred_interrupts():
        os.kill(os.getpid(), signal.SIGTERM)
        finished = sum(range(1000))  # the block runs to its end
    assert finished == 499500
    interrupts.forget_interrupts()
    interrupts.raise_if_interrupted()  # nothing recorded: no exception


def test_an_interrupt_through_exec_code_still_exits_130_not_by_sigint(tmp_path):
    # dataclasses creates __init__ with exec(); a KeyboardInterrupt passing through such code sets CPython's
    # "unhandled KeyboardInterrupt" flag, and without the reset the process kills itself with SIGINT (-2)
    script = (
        "import sys\n"
        "from mobisense import cli\n"
        "from mobisense.core import commands\n"
        "body = 'import os, signal\\nos.kill(os.getpid(), signal.SIGTERM)\\nfor _ in range(1000): pass'\n"
        "commands.ValidateCommand.run = staticmethod(lambda args: exec(body))\n"
        "sys.exit(cli.main(['validate', 'unused.yaml']))\n"
    )
    (tmp_path / "interrupted_command.py").write_text(script)  # run with -m, like the console script's exit path
    run = [sys.executable, "-m", "interrupted_command"]
    done = subprocess.run(run, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 130, done.stderr
    assert done.stderr.strip().endswith("interrupted; files already written are complete")
