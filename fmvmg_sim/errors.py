"""Error types shared by every command.

``InputError`` is bad input from the user (a scenario key, a record line, a CLI
value): the CLI turns it into a one-line message on stderr and exit code 2.
Anything else that escapes a command is an internal failure (exit code 1).
"""

from __future__ import annotations


class InputError(Exception):
    """Bad user input; rendered as ``fmvmg: <where>: <message>`` with exit code 2.

    Parameters
    ----------
    message : str
        What is wrong and what was expected.
    where : str, optional
        The file, key path or line the problem is in (for example
        ``"scenario.toml: circuit.pi.kp"`` or ``"record.csv line 17"``).
    """

    def __init__(self, message: str, where: str | None = None):
        self.message = message
        self.where = where
        super().__init__(f"{where}: {message}" if where else message)
