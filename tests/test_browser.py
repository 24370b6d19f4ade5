"""The HTML report, opened in a real browser (headless Chromium): every figure loads."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

REPORT = Path(__file__).resolve().parents[1] / "results" / "reproduction" / "report.html"
PROBE = """<script>window.addEventListener("load", () => {
  const broken = [...document.images].filter(i => !i.complete || i.naturalWidth === 0).length;
  document.body.setAttribute("data-images", document.images.length);
  document.body.setAttribute("data-broken", broken);
  document.body.setAttribute("data-tables", document.querySelectorAll("table").length);
});</script>"""


def _chromium() -> str:
    """The Chromium binary; installed from Debian's package when missing and possible."""
    for name in ("chromium", "chromium-browser"):
        if shutil.which(name):
            return shutil.which(name)  # type: ignore[return-value]
    if shutil.which("apt-get") and os.geteuid() == 0:
        subprocess.run(["apt-get", "install", "-y", "-q", "chromium"], capture_output=True, timeout=900)
        if shutil.which("chromium"):
            return shutil.which("chromium")  # type: ignore[return-value]
    pytest.skip("no Chromium: install the Debian package `chromium` (apt-get install chromium) to run this test")


@pytest.mark.slow
def test_report_renders_with_every_figure_loaded(tmp_path: Path) -> None:
    browser = _chromium()
    page = tmp_path / "report.html"
    page.write_text(REPORT.read_text().replace("</body>", PROBE + "</body>"))
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=10000"]
    dom = subprocess.run([browser, *flags, "--dump-dom", page.as_uri()], capture_output=True, text=True,
                         timeout=120).stdout
    attributes = dict(re.findall(r'data-(images|broken|tables)="(\d+)"', dom))
    assert int(attributes["images"]) >= 4 and attributes["broken"] == "0", attributes
    assert int(attributes["tables"]) >= 1
    shot = tmp_path / "report.png"
    subprocess.run([browser, *flags, "--window-size=1280,3000", f"--screenshot={shot}", page.as_uri()],
                   capture_output=True, timeout=120)
    from PIL import Image

    pixels = np.asarray(Image.open(shot).convert("L"), dtype=np.float64)
    assert pixels.std() > 10  # a page with text and figures, not a blank screen
