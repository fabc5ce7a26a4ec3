"""Open a local HTML page in headless Chromium and list what went wrong loading it.

Speaks the Chrome DevTools Protocol over ``--remote-debugging-pipe`` (file descriptors 3 and
4, messages separated by NUL bytes), so it needs nothing but the standard library and a
Chromium binary (Debian's ``chromium`` package). It records failed network loads, requests
for anything but local files, uncaught script exceptions and console errors, and asks the page
which <img> elements did not load. It can wait for a script's condition, evaluate expressions
in the page and take a screenshot of the page or of one element.

WebGL runs on SwiftShader, Chromium's software rasteriser (there is no GPU in CI): the flags
ask for it explicitly, since Chromium no longer falls back to it by itself.
"""

from __future__ import annotations

import json
import os
import select
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

FLAGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
    "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic",
    "--remote-debugging-pipe", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
    "--window-size=1280,1000",  # a viewport that holds the whole 3D view (the default: 493 px)
]
LOCAL_SCHEMES = ("file:", "data:", "blob:", "about:")

BROKEN_IMAGES = (
    "JSON.stringify(Array.from(document.images)"
    ".filter(im => !im.complete || im.naturalWidth === 0).map(im => im.src))"
)


def find_chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


def require_chromium() -> str:
    """Chromium's path; the test is skipped without one, except on CI, where it fails."""
    import pytest

    chromium = find_chromium()
    if chromium is None:
        if os.environ.get("CI") == "true":
            pytest.fail("CI must have Chromium (Debian's chromium package) for the report test")
        pytest.skip("no chromium on this machine (Debian: apt-get install chromium)")
    return chromium


@dataclass
class PageCheck:
    images: int = 0
    broken_images: list[str] = field(default_factory=list)
    failed_loads: list[dict] = field(default_factory=list)
    exceptions: list[str] = field(default_factory=list)
    console_errors: list[str] = field(default_factory=list)
    remote_requests: list[str] = field(default_factory=list)
    screenshot: bytes | None = None
    values: list = field(default_factory=list)  # what the ``evaluate`` expressions gave

    @property
    def problems(self) -> list[str]:
        return ([f"image did not load: {u}" for u in self.broken_images]
                + [f"load failed: {f.get('errorText')} ({f.get('type')})"
                   for f in self.failed_loads]
                + [f"asked the network for {u}" for u in self.remote_requests]
                + [f"script error: {e}" for e in self.exceptions]
                + [f"console error: {e}" for e in self.console_errors])


class _Pipe:
    def __init__(self, write_fd: int, read_fd: int, proc: subprocess.Popen) -> None:
        self.w, self.r, self.proc = write_fd, read_fd, proc
        self.buffer = b""
        self.events: list[dict] = []
        self.next_id = 0

    def send(self, method: str, params: dict | None = None, session: str | None = None) -> int:
        self.next_id += 1
        message = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        os.write(self.w, json.dumps(message).encode() + b"\0")
        return self.next_id

    def wait(self, predicate, deadline: float) -> dict:
        while True:
            while b"\0" in self.buffer:
                raw, self.buffer = self.buffer.split(b"\0", 1)
                message = json.loads(raw)
                self.events.append(message)
                if predicate(message):
                    return message
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError("Chromium did not answer in time")
            ready, _, _ = select.select([self.r], [], [], min(remaining, 0.5))
            if ready:
                chunk = os.read(self.r, 1 << 20)
                if not chunk:
                    err = (self.proc.stderr.read().decode(errors="replace")
                           if self.proc.stderr else "")
                    raise RuntimeError(f"Chromium closed the DevTools pipe: {err[-2000:]}")
                self.buffer += chunk

    def call(self, method: str, params: dict | None, session: str | None, deadline: float) -> dict:
        i = self.send(method, params, session)
        reply = self.wait(lambda m: m.get("id") == i, deadline)
        if "error" in reply:
            raise RuntimeError(f"{method}: {reply['error']}")
        return reply.get("result", {})


def check_page(page: str | Path, chromium: str, *, timeout: float = 60.0,
               screenshot: bool | str = False, wait_for: str | None = None,
               evaluate: tuple[str, ...] = ()) -> PageCheck:
    """Load ``page`` (a file) in headless Chromium; return what failed.

    ``wait_for``: a script expression to wait for, after the load, until it is true (a
    TimeoutError if it never is). ``evaluate``: expressions to evaluate then, in order, their
    values in ``values``. ``screenshot``: True for the whole page, or a CSS selector for the
    element to take (after the expressions ran)."""
    url = Path(page).resolve().as_uri()
    to_browser_r, to_browser_w = os.pipe()
    from_browser_r, from_browser_w = os.pipe()

    def child_fds():  # the DevTools pipe is fd 3 (commands in) and fd 4 (replies out)
        a, b = os.dup(to_browser_r), os.dup(from_browser_w)
        os.dup2(a, 3)
        os.dup2(b, 4)

    with tempfile.TemporaryDirectory(prefix="sppl-chromium-") as profile:
        proc = subprocess.Popen(
            [chromium, *FLAGS, f"--user-data-dir={profile}", "about:blank"],
            pass_fds=(3, 4), preexec_fn=child_fds,  # noqa: PLW1509 - no threads here
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        )
        os.close(to_browser_r)
        os.close(from_browser_w)
        pipe = _Pipe(to_browser_w, from_browser_r, proc)
        deadline = time.monotonic() + timeout
        result = PageCheck()
        try:
            target = pipe.call("Target.createTarget", {"url": "about:blank"}, None, deadline)
            session = pipe.call("Target.attachToTarget",
                                {"targetId": target["targetId"], "flatten": True},
                                None, deadline)["sessionId"]
            for domain in ("Page", "Network", "Runtime", "Log"):
                pipe.call(f"{domain}.enable", None, session, deadline)
            pipe.send("Page.navigate", {"url": url}, session)
            pipe.wait(lambda m: m.get("method") == "Page.loadEventFired", deadline)
            value = pipe.call("Runtime.evaluate",
                              {"expression": BROKEN_IMAGES, "returnByValue": True},
                              session, deadline)["result"]["value"]
            result.broken_images = json.loads(value)
            result.images = pipe.call("Runtime.evaluate",
                                      {"expression": "document.images.length",
                                       "returnByValue": True},
                                      session, deadline)["result"]["value"]

            def evaluate_js(expression: str):
                reply = pipe.call("Runtime.evaluate",
                                  {"expression": expression, "returnByValue": True,
                                   "awaitPromise": True}, session, deadline)
                if "exceptionDetails" in reply:
                    d = reply["exceptionDetails"]
                    raise RuntimeError(f"{expression}: "
                                       f"{d.get('exception', {}).get('description') or d}")
                return reply["result"].get("value")

            if wait_for is not None:
                while not evaluate_js(f"Boolean({wait_for})"):
                    if time.monotonic() + 1.0 > deadline:  # leave time to ask once more
                        raise TimeoutError(f"this never came true on the page: {wait_for}")
                    time.sleep(0.1)
            result.values = [evaluate_js(e) for e in evaluate]
            if screenshot:
                import base64

                params = {"format": "png", "captureBeyondViewport": True}
                if isinstance(screenshot, str):
                    # The element's content box (inside its border), in page coordinates,
                    # scrolled into view and taken as laid out: capturing beyond the viewport
                    # would lay the page out again, at another width.
                    box = evaluate_js(
                        f"(() => {{ const e = document.querySelector({json.dumps(screenshot)});"
                        " e.scrollIntoView(); const r = e.getBoundingClientRect(); return ["
                        "r.left + e.clientLeft + window.scrollX, r.top + e.clientTop + "
                        "window.scrollY, e.clientWidth, e.clientHeight]; })()")
                    params = {"format": "png",
                              "clip": dict(zip(("x", "y", "width", "height"), box), scale=1)}
                shot = pipe.call("Page.captureScreenshot", params, session, deadline)
                result.screenshot = base64.b64decode(shot["data"])
            try:
                pipe.send("Browser.close")
                proc.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                pass
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            os.close(to_browser_w)
            os.close(from_browser_r)
    for m in pipe.events:
        method, params = m.get("method"), m.get("params", {})
        if method == "Network.loadingFailed":
            result.failed_loads.append(params)
        elif method == "Network.requestWillBeSent":
            url = params.get("request", {}).get("url", "")
            if not url.startswith(LOCAL_SCHEMES):
                result.remote_requests.append(url)
        elif method == "Runtime.exceptionThrown":
            d = params.get("exceptionDetails", {})
            result.exceptions.append(d.get("exception", {}).get("description") or d.get("text", ""))
        elif method == "Log.entryAdded" and params.get("entry", {}).get("level") == "error":
            e = params["entry"]
            result.console_errors.append(f"{e.get('text')} {e.get('url', '')}".strip())
        elif method == "Runtime.consoleAPICalled" and params.get("type") == "error":
            args = params.get("args", [])
            result.console_errors.append(" ".join(str(a.get("value")) for a in args))
    return result
