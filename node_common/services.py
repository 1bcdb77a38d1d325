"""Service handlers that always answer.

A malformed request (``ValueError``, ``KeyError``: unknown task or policy,
wrong sizes, NaN) is answered with ``success=False`` and the reason; a
failure further down (the sim did not answer) likewise. An unexpected error
is logged with its traceback and answered too: a client never hangs on a
request the node choked on, and the node keeps serving. A response with an
``error`` field also gets the kind of error, for clients to act on instead
of the message's text.
"""

from __future__ import annotations

import functools
import traceback
from typing import Mapping

from node_common.calls import ServiceCallError

REFUSED = (ValueError, KeyError, ServiceCallError)


def answers_errors(what: str, kinds: Mapping[type[Exception] | tuple[type[Exception], ...], int] | None = None):
    """Decorate a ``handler(self, request, response)`` of a Node with a ``success``/``message`` response.

    ``kinds``: the response's ``error`` for each exception class (the first
    that matches, in order); the last entry should be ``Exception``.
    """

    def decorate(handler):
        @functools.wraps(handler)
        def handle(self, request, response):
            try:
                return handler(self, request, response)
            except REFUSED as error:
                caught, message = error, str(error)
                self.get_logger().warning(f"refused {what} request: {message}")
            except Exception as error:  # noqa: BLE001 - answered and logged, see module docstring
                caught, message = error, f"internal error: {type(error).__name__}: {error}"
                self.get_logger().error(f"{what} failed:\n{traceback.format_exc()}")
            response.success, response.message = False, message
            for kind, code in (kinds or {}).items():
                if isinstance(caught, kind):
                    response.error = code
                    break
            return response

        return handle

    return decorate
