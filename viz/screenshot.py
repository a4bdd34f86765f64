"""A recording as a reader sees it: served by ``rerun --serve-web``, opened in headless
Chromium (software WebGL), screenshotted once the viewer has drawn it.

Needs Debian's ``chromium`` (``apt-get install chromium``) and Python's ``playwright``; the
OCR of labels (:func:`read_text`) needs ``tesseract-ocr`` and ``pytesseract``.
"""

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

CHROMIUM = "/usr/bin/chromium"
VIEWPORT = (1280, 800)
# The 3D view of an item blueprint (viz.rerun_log.item_blueprint): the left three quarters,
# below the top bar and above the collapsed time panel, as fractions of the page.
VIEW_BOX = (0.01, 0.08, 0.72, 0.86)


def missing_tools(ocr: bool = False) -> list[str]:
    """What this machine lacks to take (and read) screenshots; empty when nothing."""
    missing = [] if Path(CHROMIUM).exists() else [f"{CHROMIUM} (apt-get install chromium)"]
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        missing.append("python package playwright")
    if ocr:
        if shutil.which("tesseract") is None:
            missing.append("tesseract (apt-get install tesseract-ocr)")
        try:
            import pytesseract  # noqa: F401
        except ImportError:
            missing.append("python package pytesseract")
    return missing


@dataclass
class Shot:
    path: Path
    view_fill: float  # share of non-background pixels inside the 3D view
    seconds: float  # from opening the page to a settled picture


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_port(port: int, deadline: float) -> None:
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    raise TimeoutError(f"rerun web viewer did not listen on port {port}")


def view_fill(image: Image.Image, box=VIEW_BOX) -> float:
    """Share of pixels in ``box`` (fractions of the image) that differ from the box's most
    common colour (its background) by more than 40 in some channel."""
    w, h = image.size
    crop = np.asarray(image.convert("RGB").crop((int(box[0] * w), int(box[1] * h),
                                                 int(box[2] * w), int(box[3] * h))), dtype=np.int16)
    flat = crop.reshape(-1, 3)
    colours, counts = np.unique(flat, axis=0, return_counts=True)
    background = colours[counts.argmax()]
    return float(np.mean(np.abs(flat - background).max(axis=1) > 40))


def screenshot(rrd: str | Path, png: str | Path, timeout_s: float = 120.0,
               settle_s: float = 4.0) -> Shot:
    """Serve ``rrd``, open it in Chromium, and save a PNG once the 3D view has content and
    two pictures ``settle_s`` apart are identical (or near: WebGL may dither)."""
    from playwright.sync_api import sync_playwright

    if missing := missing_tools():
        raise RuntimeError(f"cannot take screenshots: missing {', '.join(missing)}")
    rrd, png = Path(rrd).resolve(), Path(png)
    grpc, web = _free_port(), _free_port()
    server = subprocess.Popen(
        [sys.executable, "-m", "rerun", "--serve-web", "--bind", "127.0.0.1", "--port", str(grpc),
         "--web-viewer-port", str(web), str(rrd)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.monotonic() + timeout_s
    try:
        _wait_port(web, deadline)
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=[
                "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"])
            page = browser.new_page(viewport={"width": VIEWPORT[0], "height": VIEWPORT[1]},
                                    color_scheme="dark")
            start = time.monotonic()
            page.goto(f"http://127.0.0.1:{web}/?url=rerun%2Bhttp://127.0.0.1:{grpc}/proxy")
            previous = None
            while True:
                time.sleep(settle_s)
                page.screenshot(path=str(png))
                image = Image.open(png)
                fill = view_fill(image)
                pixels = np.asarray(image.convert("L"), dtype=np.int16)
                settled = previous is not None and np.mean(np.abs(pixels - previous) > 8) < 0.002
                if fill > 0.005 and settled:
                    browser.close()
                    return Shot(png, fill, time.monotonic() - start)
                if time.monotonic() > deadline:
                    browser.close()
                    raise TimeoutError(f"{rrd}: the viewer did not settle on a drawn 3D view in "
                                       f"{timeout_s:.0f} s (3D view fill {fill:.4f})")
                previous = pixels
    finally:  # `python -m rerun` runs the viewer binary as a child: end the whole group
        os.killpg(server.pid, signal.SIGTERM)
        try:
            server.wait(10)
        except subprocess.TimeoutExpired:
            os.killpg(server.pid, signal.SIGKILL)


def read_text(png: str | Path) -> str:
    """OCR of a screenshot (tesseract), upscaled 2× for the viewer's small fonts."""
    import pytesseract

    image = Image.open(png).convert("L")
    return pytesseract.image_to_string(image.resize((image.width * 2, image.height * 2)))


_CONFUSABLE = str.maketrans({"o": "0", "i": "1", "l": "1"})


def squash(text: str) -> str:
    """Lower-case letters and digits only, with OCR's usual confusions (o/0, i/l/1) merged:
    OCR reads ``_``, spaces and those glyphs unreliably."""
    return "".join(c for c in text.lower() if c.isalnum()).translate(_CONFUSABLE)
