"""The HTML report opened in a real browser (headless Chromium): every figure renders (decoded,
non-blank pixels), the page logs no console error, and the verdict and tables are there.

Chromium is driven over the DevTools protocol on a pipe (``--remote-debugging-pipe``: file
descriptors 3 and 4, NUL-separated JSON), so no Python browser package is needed. Skipped with
the reason when Chromium is not installed (``make test`` installs it with apt-get as root).

Screenshots for the documentation: ``python tests/test_report_browser.py report.html out.png
[--selector '#data-quality'] [--height 900]``.
"""
from __future__ import annotations

import base64
import fcntl
import io
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_browser() -> str | None:
    """Path of a Chromium-family browser, or None."""
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    return None


def _above_9(fd: int) -> int:
    """The same file as ``fd`` on a descriptor >= 10 (``fd`` closed)."""
    high = fcntl.fcntl(fd, fcntl.F_DUPFD, 10)
    os.close(fd)
    return high


class Browser:
    """A headless Chromium page driven over the DevTools protocol on a pipe."""

    def __init__(self, executable: str, width: int = 1280, height: int = 900, timeout: float = 60.0) -> None:
        self.timeout = timeout
        self.events: list[dict] = []
        self._next = 0
        self._buffer = b""
        self._profile = tempfile.mkdtemp(prefix="agvdyn-chromium-")
        to_browser_r, self._to_browser = os.pipe()
        self._from_browser, from_browser_w = os.pipe()
        # the child's ends above fd 9, so that the redirections to fds 3 and 4 cannot overwrite each other
        # (bash, not sh: dash takes single-digit descriptors only)
        to_browser_r, from_browser_w = _above_9(to_browser_r), _above_9(from_browser_w)
        args = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--hide-scrollbars",
                "--no-first-run", "--no-default-browser-check", "--disable-extensions", "--mute-audio",
                f"--user-data-dir={self._profile}", "--remote-debugging-pipe", f"--window-size={width},{height}",
                "about:blank"]
        # the browser reads commands on fd 3 and writes replies and events on fd 4
        self._proc = subprocess.Popen(
            ["bash", "-c", f'exec "$0" "$@" 3<&{to_browser_r} 4>&{from_browser_w}', executable, *args],
            pass_fds=(to_browser_r, from_browser_w), stdout=subprocess.DEVNULL,
            stderr=open(os.path.join(self._profile, "stderr.log"), "wb"))
        os.close(to_browser_r)
        os.close(from_browser_w)
        target = self.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        self.session = self.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        for domain in ("Page", "Runtime", "Log"):
            self.send(f"{domain}.enable", session=True)
        self.send("Emulation.setDeviceMetricsOverride",
                  {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False}, session=True)

    def _read(self) -> dict:
        while b"\0" not in self._buffer:
            import select

            ready, _, _ = select.select([self._from_browser], [], [], self.timeout)
            if not ready:
                raise TimeoutError(f"no answer from the browser in {self.timeout} s")
            chunk = os.read(self._from_browser, 1 << 20)
            if not chunk:
                log = Path(self._profile, "stderr.log").read_text(errors="replace")[-2000:]
                raise RuntimeError(f"the browser closed the DevTools pipe; its last words:\n{log}")
            self._buffer += chunk
        message, _, self._buffer = self._buffer.partition(b"\0")
        return json.loads(message)

    def send(self, method: str, params: dict | None = None, *, session: bool = False) -> dict:
        """Send one command and return its result (events that arrive meanwhile are kept)."""
        self._next += 1
        message = {"id": self._next, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = self.session
        os.write(self._to_browser, json.dumps(message).encode() + b"\0")
        while True:
            reply = self._read()
            if reply.get("id") == self._next:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})
            self.events.append(reply)

    def wait_for(self, method: str) -> dict:
        """Wait for an event (or return one that already arrived)."""
        deadline = time.monotonic() + self.timeout
        while time.monotonic() < deadline:
            for event in self.events:
                if event.get("method") == method:
                    self.events.remove(event)
                    return event
            self.events.append(self._read())
        raise TimeoutError(f"no {method} in {self.timeout} s")

    def open(self, url: str) -> None:
        self.send("Page.navigate", {"url": url}, session=True)
        self.wait_for("Page.loadEventFired")

    def evaluate(self, expression: str):
        result = self.send("Runtime.evaluate", {"expression": expression, "returnByValue": True,
                                                "awaitPromise": True}, session=True)
        if "exceptionDetails" in result:
            raise RuntimeError(f"{expression[:60]}...: {result['exceptionDetails']}")
        return result["result"].get("value")

    def errors(self) -> list[str]:
        """Console errors, uncaught exceptions and browser log errors seen so far."""
        out = []
        for e in self.events:
            method, params = e.get("method"), e.get("params", {})
            if method == "Runtime.exceptionThrown":
                out.append(str(params.get("exceptionDetails", {}).get("text")))
            elif method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
                out.append(" ".join(str(a.get("value", a.get("description"))) for a in params.get("args", [])))
            elif method == "Log.entryAdded" and params.get("entry", {}).get("level") == "error":
                out.append(str(params["entry"].get("text")))
        return out

    def screenshot(self, clip: dict | None = None) -> bytes:
        """PNG of the viewport, or of ``clip`` (x, y, width, height in page pixels)."""
        params: dict = {"format": "png", "captureBeyondViewport": clip is not None}
        if clip is not None:
            params["clip"] = {**clip, "scale": 1}
        return base64.b64decode(self.send("Page.captureScreenshot", params, session=True)["data"])

    def close(self) -> None:
        try:
            self.send("Browser.close")
        except (RuntimeError, OSError, TimeoutError):
            pass
        try:
            self._proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
        for fd in (self._to_browser, self._from_browser):
            try:
                os.close(fd)
            except OSError:
                pass
        shutil.rmtree(self._profile, ignore_errors=True)

    def __enter__(self) -> "Browser":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


_IMAGES = """Array.from(document.images).map(img => {
  const r = img.getBoundingClientRect();
  return {alt: img.alt, complete: img.complete, naturalWidth: img.naturalWidth, naturalHeight: img.naturalHeight,
          x: r.left + window.scrollX, y: r.top + window.scrollY, width: r.width, height: r.height};
})"""


def image_statistics(png: bytes) -> tuple[float, float]:
    """(fraction of pixels that are not near-white, standard deviation of the grey levels)."""
    import numpy as np
    from PIL import Image

    grey = np.asarray(Image.open(io.BytesIO(png)).convert("L"), dtype=float)
    return float(np.mean(grey < 235)), float(grey.std())


def take_screenshot(html: Path, out: Path, *, selector: str | None = None, height: int = 900,
                    width: int = 1280) -> Path:
    """Screenshot of a report at ``width`` px: the top ``height`` px, or from the element
    ``selector`` on."""
    executable = find_browser()
    if executable is None:
        raise RuntimeError("no Chromium found")
    with Browser(executable, width=width, height=height) as browser:
        browser.open(html.resolve().as_uri())
        top = 0.0
        if selector is not None:
            top = browser.evaluate(f"document.querySelector({json.dumps(selector)}).getBoundingClientRect().top"
                                   " + window.scrollY - 8")
        out.write_bytes(browser.screenshot({"x": 0, "y": top, "width": width, "height": height}))
    return out


# ---------------------------------------------------------------------------------------------- tests

BROWSER = find_browser()
needs_browser = pytest.mark.skipif(
    BROWSER is None, reason="Chromium is not installed (apt-get install chromium; `make test` installs it when "
                            "run as root)")


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    """Two reports: the prototype identified and validated, and another vehicle refused."""
    from typer.testing import CliRunner

    from agvdyn.cli import app
    from agvdyn.io import write_log
    from agvdyn.platform import PROTOTYPE, Geometry
    from model_logs import identification_frame, lane_change_frame

    root = tmp_path_factory.mktemp("browser")
    short = {"steer_left": 6.0, "steer_right": 6.0, "straight": 6.0, "rotation": 6.0}
    ident, lane = root / "ident.parquet", root / "lane.parquet"
    write_log(ident, identification_frame(short, align=1.0)[0], {"platform": PROTOTYPE.to_dict()})
    write_log(lane, lane_change_frame(8.0)[0])
    other = Geometry(l=0.9, b=0.6, a=0.03, r=0.08, i_G=18.0, name="cart")
    straight = root / "straight.parquet"
    write_log(straight, identification_frame({"straight": 6.0}, geometry=other)[0], {"platform": other.to_dict()})
    runner = CliRunner()
    ok = root / "ok.html"
    # exact model logs: the HAC covariance, as in test_report (the jackknife's few blocks may warn)
    result = runner.invoke(app, ["report", "--ident", str(ident), "--validation", str(lane), "--out", str(ok),
                                 "--uncertainty", "hac"])
    assert result.exit_code == 0, result.output
    refused = root / "refused.html"
    result = runner.invoke(app, ["report", "--ident", str(straight), "--out", str(refused)])
    assert result.exit_code == 1, result.output
    return {"ok": ok, "refused": refused}


@needs_browser
@pytest.mark.parametrize("which, verdict, figures", [("ok", "Identified", 6), ("refused", "Refused", 1)])
def test_report_renders_in_chromium(reports, which, verdict, figures):
    with Browser(BROWSER, width=1280, height=900) as browser:
        browser.open(reports[which].resolve().as_uri())
        images = browser.evaluate(_IMAGES)
        page = browser.evaluate("({width: document.documentElement.scrollWidth, "
                                "height: document.documentElement.scrollHeight, text: document.body.innerText, "
                                "tables: document.querySelectorAll('table').length, "
                                "verdict: document.querySelector('#verdict .label').innerText})")
        shots = [browser.screenshot({k: img[k] for k in ("x", "y", "width", "height")}) for img in images]
        errors = browser.errors()
    assert errors == []
    page["text"] = page["text"].replace("\xa0", " ")
    assert page["verdict"] == verdict
    assert page["width"] <= 1280  # nothing wider than the window: no horizontal scrolling
    assert len(images) == figures
    for img, png in zip(images, shots):
        assert img["complete"] and img["naturalWidth"] > 300 and img["naturalHeight"] > 150, img["alt"]
        assert img["width"] > 300, img["alt"]  # laid out, not collapsed
        ink, spread = image_statistics(png)
        assert 0.01 < ink < 0.9 and spread > 10, (img["alt"], ink, spread)  # drawn, neither blank nor a block
    for heading in ("Data quality", "Provenance", "Rows kept per motion mode", "SHA-256"):
        assert heading in page["text"]
    if which == "ok":
        assert page["tables"] >= 10
        for heading in ("Parameters", "Correlation of the estimates", "Residuals", "cf. Fig. 5", "cf. Fig. 6",
                        "95 % interval"):
            assert heading in page["text"]
    else:
        assert "do not determine" in page["text"] and "Correlation of the estimates" not in page["text"]


def main(argv: list[str]) -> int:
    import argparse

    parser = argparse.ArgumentParser(description="Screenshot of an HTML report with headless Chromium.")
    parser.add_argument("html", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--selector")
    parser.add_argument("--height", type=int, default=900)
    parser.add_argument("--width", type=int, default=1280)
    args = parser.parse_args(argv)
    print(take_screenshot(args.html, args.out, selector=args.selector, height=args.height, width=args.width))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
