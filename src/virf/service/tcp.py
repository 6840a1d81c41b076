"""HTTP connections that send each answer at once.

With ``virf serve --workers N`` uvicorn binds the listening socket itself,
with protocol number 0.  asyncio recognises TCP by that number, so it left
Nagle's algorithm on for the connections the workers accept, and every
answer waited about 40 ms for the client's delayed acknowledgement
(measured: 1.5 ms a request with one worker, 44 ms with two, for an app that
does nothing).  This protocol switches it off itself.  It is uvicorn's h11
protocol, the one uvicorn picks when httptools is not installed (VIRF does
not install it).
"""

from __future__ import annotations

import asyncio
import contextlib
import socket

from uvicorn.protocols.http.h11_impl import H11Protocol


class NoDelayH11Protocol(H11Protocol):
    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        sock = transport.get_extra_info("socket")
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        super().connection_made(transport)
