"""The dashboard's web server (aiohttp): one page, its static assets, and a WebSocket that pushes
the node's state at ``rate_hz`` and takes the page's teach/cancel/save commands. Who may steer
(token, ``Origin``, loopback ``Host``, ``read_only``, ``MAX_SOCKETS``, refusals logged and
answered, never passed to the node): docs/dashboard.md, "Who may steer".
"""

from __future__ import annotations

import asyncio
import hmac
import ipaddress
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from typing import Any
from urllib.parse import urlsplit

from aiohttp import WSMsgType, web

from .commands import MAX_MESSAGE_BYTES, CommandRefused, parse_command
from .state import diagnostics_view, estimate_view, kernels_view, link_view

log = logging.getLogger("gait_estimator.dashboard")
STATIC = resources.files("gait_estimator.dashboard") / "static"
TOKEN_ENV = "GAIT_DASHBOARD_TOKEN"
MAX_COMMANDS_PER_S = 5.0
MAX_SOCKETS = 4


@dataclass(frozen=True)
class ServerOptions:
    """host/port to bind; ``token`` (None: none asked); ``read_only``; frames per second."""

    host: str = "127.0.0.1"
    port: int = 8080
    token: str | None = None
    read_only: bool = False
    rate_hz: float = 30.0


def is_loopback(host: str) -> bool:
    """True for ``localhost`` and loopback addresses."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class _Throttled:
    """Log a refusal at most once a second per reason, with the count of those not logged."""

    def __init__(self) -> None:
        self.last: dict[str, float] = {}
        self.skipped: dict[str, int] = {}

    def warn(self, reason: str, peer: str) -> None:
        now = time.monotonic()
        key = reason.split(":")[0]
        if now - self.last.get(key, -math.inf) < 1.0:
            self.skipped[key] = self.skipped.get(key, 0) + 1
            return
        self.last[key] = now
        more = self.skipped.pop(key, 0)
        log.warning("refused a socket message from %s: %s%s", peer, reason, f" ({more} more refused)" if more else "")


class Dashboard:
    """The server around one ``DashboardLink`` (``ros/dashboard_client.py``)."""

    def __init__(self, link: Any, options: ServerOptions) -> None:
        self.link = link
        self.options = options
        self.refusals = _Throttled()
        self.sockets = 0

    # -- access

    def _denied(self, request: web.Request) -> web.Response | None:
        token = self.options.token
        if token is None:  # loopback only: a page that reached it by a rebound name is another site's
            if not is_loopback(urlsplit(f"//{request.host}").hostname or ""):
                log.warning("refused %s %s from %s: Host %r is not loopback", request.method, request.path,
                            request.remote, request.host)
                return web.Response(status=403, text="403: open this dashboard as 127.0.0.1 or localhost\n")
            return None
        given = request.query.get("token")
        auth = request.headers.get("Authorization", "")
        if given is None and auth.startswith("Bearer "):
            given = auth[len("Bearer "):]
        if not given:
            log.warning("refused %s %s from %s: no token", request.method, request.path, request.remote)
            return web.Response(status=401, text="401: this dashboard needs its token (?token=...)\n")
        if not hmac.compare_digest(given.encode(), token.encode()):
            log.warning("refused %s %s from %s: wrong token", request.method, request.path, request.remote)
            return web.Response(status=403, text="403: wrong token\n")
        return None

    async def index(self, request: web.Request) -> web.StreamResponse:
        denied = self._denied(request)
        if denied is not None:
            return denied
        html = (STATIC / "index.html").read_text(encoding="utf-8")
        return web.Response(text=html, content_type="text/html", headers={
            "Cache-Control": "no-store", "Content-Security-Policy": "default-src 'self'; connect-src 'self'"})

    async def static(self, request: web.Request) -> web.StreamResponse:
        name = request.match_info["name"]
        files = {"app.js": "application/javascript", "app.css": "text/css",
                 "uPlot.iife.min.js": "application/javascript", "uPlot.min.css": "text/css"}
        if name not in files:
            raise web.HTTPNotFound()
        path = STATIC / ("vendor/uplot/" + name if name.startswith("uPlot") else name)
        return web.Response(body=path.read_bytes(), content_type=files[name])

    # -- socket

    async def socket(self, request: web.Request) -> web.StreamResponse:
        denied = self._denied(request)
        if denied is not None:
            return denied
        origin = request.headers.get("Origin")
        if origin and urlsplit(origin).netloc != request.host:
            log.warning("refused a socket from %s: Origin %s is not this server", request.remote, origin)
            return web.Response(status=403, text="403: cross-site socket\n")
        if self.sockets >= MAX_SOCKETS:
            log.warning("refused a socket from %s: %d pages already open", request.remote, self.sockets)
            return web.Response(status=503, text=f"503: at most {MAX_SOCKETS} pages at once\n")
        self.sockets += 1
        sender: asyncio.Task[None] | None = None
        peer = str(request.remote)
        ws = web.WebSocketResponse(max_msg_size=MAX_MESSAGE_BYTES, heartbeat=10.0)
        try:
            await ws.prepare(request)
            log.info("page connected from %s", peer)
            await ws.send_json({"type": "hello", "node": self.link.target, "read_only": self.options.read_only,
                                "rate_hz": self.options.rate_hz})
            sender = asyncio.create_task(self._send_frames(ws))
            budget, refill = MAX_COMMANDS_PER_S, time.monotonic()
            async for msg in ws:
                if msg.type == WSMsgType.ERROR:  # e.g. a message over MAX_MESSAGE_BYTES: aiohttp closes the socket
                    self.refusals.warn(f"socket closed: {ws.exception()}", peer)
                    break
                if msg.type == WSMsgType.CLOSE:
                    break
                now = time.monotonic()
                budget, refill = min(MAX_COMMANDS_PER_S, budget + (now - refill) * MAX_COMMANDS_PER_S), now
                if budget < 1.0:
                    await self._refuse(ws, peer, "too many messages (at most 5 a second)")
                    continue
                budget -= 1.0
                await self._command(ws, peer, msg.data if msg.type == WSMsgType.TEXT else b"")
        finally:
            self.sockets -= 1
            if sender is not None:
                sender.cancel()
            log.info("page from %s disconnected", peer)
        return ws

    async def _refuse(self, ws: web.WebSocketResponse, peer: str, reason: str) -> None:
        self.refusals.warn(reason, peer)
        if not ws.closed:
            await ws.send_json({"type": "reply", "ok": False, "text": f"refused: {reason}"})

    async def _command(self, ws: web.WebSocketResponse, peer: str, data: str | bytes) -> None:
        if self.options.read_only:
            await self._refuse(ws, peer, "read-only dashboard")
            return
        try:
            cmd = parse_command(data)
        except CommandRefused as exc:
            await self._refuse(ws, peer, str(exc))
            return
        log.info("%s from %s", cmd, peer)
        link = self.link
        future = link.teach(cmd.mode, cmd.strides) if cmd.op == "teach" else (
            link.cancel() if cmd.op == "cancel" else link.save())
        try:
            text, ok = await asyncio.wrap_future(future), True
        except Exception as exc:  # the node's refusal or no answer: one line to the page
            text, ok = str(exc), False
        if not ws.closed:
            await ws.send_json({"type": "reply", "op": cmd.op, "ok": ok, "text": text})

    def frame(self, cursors: list[int]) -> dict[str, Any]:
        """The next frame for a page whose angle/log cursors are ``cursors`` (updated in place)."""
        snap = self.link.snapshot(cursors[0], cursors[1])
        cursors[0], cursors[1] = snap.angles_cursor, snap.log_cursor
        now = time.monotonic()
        age = (now - snap.estimate_at) if math.isfinite(snap.estimate_at) else math.inf
        diag_age = (now - snap.diagnostics_at) if math.isfinite(snap.diagnostics_at) else math.inf
        return {
            "type": "frame",
            "link": link_view(snap.present, snap.ever_seen, age, diag_age, self.link.target),
            "estimate": estimate_view(snap.names, snap.values) if snap.names else None,
            "estimates": snap.estimates,
            "source_ns": snap.estimate_source_ns,
            "diagnostics": diagnostics_view(snap.level, snap.message, snap.diagnostics),
            "angles": snap.angles,
            "log": snap.log,
            "library_version": snap.library_version,
        }

    async def _send_frames(self, ws: web.WebSocketResponse) -> None:
        cursors = [self.link.snapshot(0, 0).angles_cursor, 0]
        library_version = -1
        period = 1.0 / self.options.rate_hz
        try:
            while not ws.closed:
                started = time.monotonic()
                frame = self.frame(cursors)
                if frame["library_version"] != library_version:
                    snap = self.link.snapshot(cursors[0], cursors[1])
                    library_version = snap.library_version
                    await ws.send_json(kernels_view(snap.library, snap.library_note))
                await ws.send_json(frame)
                await asyncio.sleep(max(0.0, period - (time.monotonic() - started)))
        except (ConnectionResetError, RuntimeError):
            return  # the page went away
        except Exception:  # a frame that cannot be built: logged; the server and the other pages go on
            log.exception("frames to a page stopped")

    # -- app

    def app(self) -> web.Application:
        app = web.Application(client_max_size=MAX_MESSAGE_BYTES)
        app.router.add_get("/", self.index)
        app.router.add_get("/ws", self.socket)
        app.router.add_get("/static/{name}", self.static)
        return app


async def serve(dashboard: Dashboard, on_ready: Callable[[str], None], stop: asyncio.Event) -> None:
    """Serve until ``stop`` is set; ``on_ready(url)`` once listening (the token in the URL)."""
    runner = web.AppRunner(dashboard.app(), access_log=None, handle_signals=False)
    await runner.setup()
    opts = dashboard.options
    site = web.TCPSite(runner, opts.host, opts.port)
    try:
        await site.start()
        port = runner.addresses[0][1] if runner.addresses else opts.port
        host = f"[{opts.host}]" if ":" in opts.host else opts.host
        on_ready(f"http://{host}:{port}/" + (f"?token={opts.token}" if opts.token else ""))
        await stop.wait()
    finally:
        await runner.cleanup()
