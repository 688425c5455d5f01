"""A headless Chromium driven over the DevTools protocol, to look at the map as a person would.

Used by the end-to-end tests and benchmarks/viewer_bench.py: load the page, read the DOM, click
where a button is on screen, take a screenshot. Needs the `chromium` binary (Debian package);
`find_chromium()` is None without it. Nothing is downloaded.
"""
from __future__ import annotations

import asyncio
import base64
import itertools
import json
import os
import re
import shutil
import signal
import subprocess
import tempfile
from pathlib import Path

import websockets

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--hide-scrollbars", "--mute-audio")
_LISTENING = re.compile(rb"DevTools listening on (ws://\S+)")


def find_chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


class BrowserError(RuntimeError):
    """Chromium did not start, or a DevTools command failed (the message says which)."""


class Browser:
    """One headless Chromium with a fresh profile and one page (tab)."""

    def __init__(self, width: int = 1280, height: int = 800, binary: str | None = None):
        self.width, self.height = width, height
        self.binary = binary or find_chromium()
        if self.binary is None:
            raise BrowserError("no chromium on PATH (Debian: apt-get install chromium)")
        self._ids = itertools.count(1)
        self._pending: dict[int, asyncio.Future] = {}
        self._loaded: list[asyncio.Future] = []
        self.console: list[str] = []

    async def __aenter__(self) -> "Browser":
        self._profile = tempfile.mkdtemp(prefix="viewer-chromium-")
        self.process = subprocess.Popen(
            [self.binary, *FLAGS, f"--user-data-dir={self._profile}", f"--window-size={self.width},{self.height}",
             "--remote-debugging-port=0", "--remote-debugging-address=127.0.0.1", "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
        url = await asyncio.wait_for(asyncio.to_thread(self._devtools_url), 30)
        self._ws = await websockets.connect(url, max_size=64 * 1024 * 1024, compression=None)
        self._reader = asyncio.create_task(self._read())
        target = await self.send("Target.createTarget", url="about:blank")
        session = await self.send("Target.attachToTarget", targetId=target["targetId"], flatten=True)
        self.session = session["sessionId"]
        await self.send("Page.enable", session=True)
        await self.send("Runtime.enable", session=True)
        await self.send("Emulation.setDeviceMetricsOverride", session=True, width=self.width, height=self.height,
                        deviceScaleFactor=1, mobile=False)
        return self

    def _devtools_url(self) -> str:
        seen = b""
        for line in iter(self.process.stderr.readline, b""):
            seen += line
            match = _LISTENING.search(line)
            if match:
                return match.group(1).decode()
        raise BrowserError(f"chromium exited ({self.process.wait()}): {seen.decode(errors='replace')[-500:]}")

    async def __aexit__(self, *exc) -> None:
        self._reader.cancel()
        await self._ws.close()
        try:
            os.killpg(self.process.pid, signal.SIGTERM)
            await asyncio.to_thread(self.process.wait, 10)
        except (ProcessLookupError, subprocess.TimeoutExpired):
            os.killpg(self.process.pid, signal.SIGKILL)
        self.process.stderr.close()
        shutil.rmtree(self._profile, ignore_errors=True)

    async def _read(self) -> None:
        async for raw in self._ws:
            message = json.loads(raw)
            future = self._pending.pop(message.get("id", -1), None)
            if future is not None and not future.done():
                future.set_result(message)
            elif message.get("method") == "Page.loadEventFired":
                for waiter in self._loaded:
                    if not waiter.done():
                        waiter.set_result(None)
                self._loaded = []
            elif message.get("method") == "Runtime.consoleAPICalled":
                args = message["params"].get("args", [])
                self.console.append(" ".join(str(a.get("value", a.get("description", ""))) for a in args))
            elif message.get("method") == "Runtime.exceptionThrown":
                self.console.append("exception: " + json.dumps(message["params"]["exceptionDetails"])[:500])

    async def send(self, method: str, session: bool = False, **params) -> dict:
        ident = next(self._ids)
        future = asyncio.get_running_loop().create_future()
        self._pending[ident] = future
        command = {"id": ident, "method": method, "params": params}
        if session:
            command["sessionId"] = self.session
        await self._ws.send(json.dumps(command))
        reply = await asyncio.wait_for(future, 30)
        if "error" in reply:
            raise BrowserError(f"{method}: {reply['error'].get('message')}")
        return reply.get("result", {})

    async def goto(self, url: str, timeout: float = 30.0) -> None:
        """Open `url` and wait for its load event (the page's scripts have run)."""
        loaded = asyncio.get_running_loop().create_future()
        self._loaded.append(loaded)
        reply = await self.send("Page.navigate", session=True, url=url)
        if reply.get("errorText"):
            raise BrowserError(f"{url}: {reply['errorText']}")
        await asyncio.wait_for(loaded, timeout)

    async def evaluate(self, expression: str):
        """The JSON value of a JavaScript expression in the page."""
        result = await self.send("Runtime.evaluate", session=True, expression=expression, returnByValue=True,
                                 awaitPromise=True)
        if "exceptionDetails" in result:
            raise BrowserError(f"{expression[:80]}: {result['exceptionDetails'].get('text')}")
        return result["result"].get("value")

    async def _middle(self, selector: str) -> tuple[float, float]:
        return tuple(await self.evaluate(
            f"(() => {{ const r = document.querySelector({json.dumps(selector)}).getBoundingClientRect();"
            f" return [r.x + r.width / 2, r.y + r.height / 2]; }})()"))

    async def click(self, selector: str) -> None:
        """Press and release the mouse at the middle of the element, as a person clicks."""
        x, y = await self._middle(selector)
        for kind in ("mouseMoved", "mousePressed", "mouseReleased"):
            await self.send("Input.dispatchMouseEvent", session=True, type=kind, x=x, y=y, button="left", clickCount=1)

    async def hover(self, selector: str) -> None:
        x, y = await self._middle(selector)
        await self.send("Input.dispatchMouseEvent", session=True, type="mouseMoved", x=x, y=y)

    async def wheel(self, selector: str, delta_y: float) -> None:
        """Turn the mouse wheel over the middle of the element (negative: away from you, zoom in)."""
        x, y = await self._middle(selector)
        await self.send("Input.dispatchMouseEvent", session=True, type="mouseWheel", x=x, y=y, deltaX=0,
                        deltaY=delta_y)

    async def screenshot(self, path: Path) -> Path:
        shot = await self.send("Page.captureScreenshot", session=True, format="png")
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(base64.b64decode(shot["data"]))
        return path
