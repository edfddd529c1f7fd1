"""gym 0.21's ``logger``: levels and ``set_level``, messages to stderr."""

from __future__ import annotations

import sys

DEBUG = 10
INFO = 20
WARN = 30
ERROR = 40
DISABLED = 50

MIN_LEVEL = WARN


def set_level(level: int) -> None:
    global MIN_LEVEL
    MIN_LEVEL = level


def _log(level: int, name: str, msg: str, *args) -> None:
    if level >= MIN_LEVEL:
        sys.stderr.write(f"{name}: {msg % args if args else msg}\n")


def debug(msg: str, *args) -> None:
    _log(DEBUG, "DEBUG", msg, *args)


def info(msg: str, *args) -> None:
    _log(INFO, "INFO", msg, *args)


def warn(msg: str, *args) -> None:
    _log(WARN, "WARN", msg, *args)


def error(msg: str, *args) -> None:
    _log(ERROR, "ERROR", msg, *args)


warning = warn
