"""The ``armreach`` command writes each of armreach's warnings once, as Python would write it."""

from __future__ import annotations

import logging

import pytest

from armreach_core.cli import _warnings_once

LOG = logging.getLogger("armreach.robot")


def test_a_command_writes_each_warning_once_and_the_next_command_again(monkeypatch, capsys) -> None:
    monkeypatch.setattr(logging.getLogger(), "handlers", [])  # a program that configured no logging
    for _ in range(2):  # two commands in one process, such as a notebook's
        with _warnings_once():
            for link in ("base", "base", "link1", "base"):
                LOG.warning("inertia of %r repaired", link)
            LOG.error("an error is written once too")
            LOG.error("a malformed call %d", "x")  # reported as logging reports it, not raised
            LOG.info("below a warning: not written")
        LOG.warning("after the command")  # Python's own handler again, the command's is gone
    err = capsys.readouterr().err
    assert err.count("inertia of 'base' repaired\n") == 2 and err.count("inertia of 'link1' repaired\n") == 2
    assert err.count("an error is written once too\n") == 2 and err.count("--- Logging error ---") == 2
    assert err.count("after the command\n") == 2 and "below a warning" not in err
    assert not any(isinstance(h, logging.StreamHandler) for h in logging.getLogger("armreach").handlers)


def test_a_program_that_configured_logging_gets_every_record(caplog: pytest.LogCaptureFixture, capsys) -> None:
    with caplog.at_level(logging.WARNING, logger="armreach"), _warnings_once():
        LOG.warning("inertia of %r repaired", "base")
        LOG.warning("inertia of %r repaired", "base")
    assert [r.getMessage() for r in caplog.records] == ["inertia of 'base' repaired"] * 2
    assert capsys.readouterr().err == ""
