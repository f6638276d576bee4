"""What the command-line tools share: the name the user typed, for their messages."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import NoReturn


def program_name(script: str) -> str:
    """The command as the user typed it: an installed console script (`hyperstate-run`), else `script`, the
    file's path in the repository (`evaluation/run.py`)."""
    typed = Path(sys.argv[0]).name if sys.argv and sys.argv[0] else ""
    return typed if typed.startswith("hyperstate-") else script


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (`prog: error: ... (--help for usage)`), exit code 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (--help for usage)\n")


class UsageError(Exception):
    """A bad command line: reported in one line, exit code 2, nothing written."""
