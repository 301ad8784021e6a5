"""The view's web server (aiohttp): the static page, a WebSocket of live updates and commands, a stats endpoint.

    with ViewServer("socket://127.0.0.1:5555", geometry=geometry) as view:   # serves on 127.0.0.1, any port
        print(view.address)                                               # http://127.0.0.1:PORT/

Routes: ``/`` the page (`static/index.html`), ``/static/*`` its script and style (shipped in the package,
nothing from a CDN), ``/ws`` the WebSocket (server -> page: `eyehil.drivers.view.payload` messages as JSON text and
camera images as binary; page -> server: JSON commands ``{"cmd": "start" | "stop" | "script" | "calibrate" |
"blink" | "fps", ...}``), ``/stats`` JSON health of the view itself (pages connected, messages dropped, the
frame rates the pages report). The server runs its own event loop on a thread; the device session
(`eyehil.drivers.view.session.ViewSession`) runs on another. Loopback by default: the page can drive the device.
"""

from __future__ import annotations

import asyncio
import json
import threading
from pathlib import Path

from aiohttp import WSMsgType, web

from eyehil.drivers.view.hub import Hub
from eyehil.drivers.view.payload import dumps
from eyehil.drivers.view.session import ViewSession

STATIC = Path(__file__).with_name("static")
MAX_COMMAND_BYTES = 4096
MAX_PAGES = 16  # WebSocket connections at a time (each has a bounded queue)
PAGE_COMMANDS = ("start", "stop", "script", "calibrate", "blink")


class ViewServer:
    """The page server and its device session; see the module docstring. Keyword arguments go to `ViewSession`."""

    def __init__(self, url: str, *, host: str = "127.0.0.1", port: int = 0, **session_options) -> None:
        self.url, self.host, self.port = url, host, port
        self.session_options = session_options
        self.session: ViewSession | None = None
        self.hub: Hub | None = None
        self.page_fps: dict[int, float] = {}  # the frame rate each page reports (images drawn per second)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._runner: web.AppRunner | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._failure: BaseException | None = None

    @property
    def address(self) -> str:
        return f"http://{self.host}:{self.port}/"

    # --- life ---------------------------------------------------------------------------------
    def start(self) -> ViewServer:
        """Serve on a thread; return once the socket listens (raise if it could not)."""
        self._thread = threading.Thread(target=self._serve, name="eyehil-view-http", daemon=True)
        self._thread.start()
        self._ready.wait(30)
        if self._failure is not None:
            self._thread.join(timeout=10)  # the thread is ending: let it, so that nothing outlives the failure
            raise self._failure
        return self

    def _serve(self) -> None:
        loop = self._loop = asyncio.new_event_loop()
        try:
            loop.run_until_complete(self._setup())
        except BaseException as exc:  # reported by start()
            self._failure = exc
            self._ready.set()
            loop.close()
            return
        self._ready.set()
        try:
            loop.run_forever()
        finally:
            loop.run_until_complete(self._runner.cleanup())
            loop.close()

    async def _setup(self) -> None:
        self.hub = Hub(asyncio.get_running_loop())
        app = web.Application()
        app.router.add_get("/", self._index)
        app.router.add_get("/ws", self._websocket)
        app.router.add_get("/stats", self._stats)
        app.router.add_static("/static/", STATIC)
        self._runner = web.AppRunner(app, access_log=None)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.port)
        await site.start()
        self.port = self._runner.addresses[0][1]
        self.session = ViewSession(self.url, self.hub.publish_threadsafe, **self.session_options).start()

    def close(self) -> None:
        """Stop the session and the server; idempotent."""
        if self.session is not None:
            self.session.close()
            self.session = None
        loop, self._loop = self._loop, None
        if loop is not None and loop.is_running():
            loop.call_soon_threadsafe(loop.stop)
        if self._thread is not None:
            self._thread.join(timeout=10)

    def __enter__(self) -> ViewServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- handlers -----------------------------------------------------------------------------
    async def _index(self, request: web.Request) -> web.FileResponse:
        return web.FileResponse(STATIC / "index.html")

    async def _stats(self, request: web.Request) -> web.Response:
        session = self.session
        return web.json_response({
            "pages": len(self.hub.clients), "view_dropped": self.hub.dropped,
            "page_fps": list(self.page_fps.values()),
            "session": {} if session is None else dict(session.counters),
            "host": {} if session is None or session.tracker is None else session.tracker.stats.as_dict(),
        })

    async def _websocket(self, request: web.Request) -> web.StreamResponse:
        if len(self.hub.clients) >= MAX_PAGES:
            return web.Response(status=503, text=f"at most {MAX_PAGES} pages at a time")
        ws = web.WebSocketResponse(heartbeat=10.0, max_msg_size=MAX_COMMAND_BYTES)
        await ws.prepare(request)
        client = self.hub.attach()
        sender = asyncio.create_task(self._send(ws, client))
        try:
            async for message in ws:
                if message.type == WSMsgType.TEXT:
                    self._command(id(client), message.data)
        finally:
            sender.cancel()
            self.hub.detach(client)
            self.page_fps.pop(id(client), None)
        return ws

    async def _send(self, ws: web.WebSocketResponse, client) -> None:
        """Send the page its messages as they come; a page that went away ends this (its queue was bounded)."""
        try:
            while not ws.closed:
                for message in await client.get_all():
                    if isinstance(message, bytes):
                        await ws.send_bytes(message)
                    else:
                        await ws.send_str(dumps(message))
        except (ConnectionError, RuntimeError):  # closed under us
            return

    def _command(self, page: int, text: str) -> None:
        """A page's command: checked, then queued for the session (malformed ones are ignored)."""
        try:
            command = json.loads(text)
        except ValueError:
            return
        if not isinstance(command, dict) or not isinstance(command.get("cmd"), str):
            return
        if command["cmd"] == "fps":
            value = command.get("value")
            if isinstance(value, int | float) and 0 <= value <= 10_000:
                self.page_fps[page] = float(value)
            return
        if command["cmd"] in PAGE_COMMANDS and self.session is not None:
            self.session.submit({k: v for k, v in command.items() if isinstance(v, str | int | float)})


