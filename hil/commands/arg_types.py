"""argparse types shared by the command modules: connection strings checked by role (common.connection)."""

from __future__ import annotations

import argparse

from common import connection


def endpoint(role: connection.Role):
    """An argparse type checking a connection string for ``role`` (common.connection)."""
    def check(text: str) -> str:
        try:
            connection.parse(text, role)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return text
    check.__name__ = "connection string"
    return check


sending = endpoint(connection.SEND_UDP)
receiving = endpoint(connection.RECEIVE_UDP)
