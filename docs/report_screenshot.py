"""Make docs/report-top.png, the top of the report page the README shows.

    pip install '.[browser]' && apt-get install chromium
    python docs/report_screenshot.py

It writes the page of the stored results (estim report) to a temporary file, opens it in
headless Chromium through Playwright (as tests/test_report_browser.py does) and captures
the first 1400 x 900 pixels.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from playwright.sync_api import sync_playwright

ROOT = Path(__file__).resolve().parents[1]
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        page_file = Path(tmp) / "report.html"
        subprocess.run([sys.executable, "-m", "estim.cli.main", "report", "--results",
                        str(ROOT / "results"), "--out", str(page_file)], check=True, cwd=ROOT)
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=shutil.which("chromium"), args=FLAGS)
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.goto(page_file.as_uri())
            page.screenshot(path=str(ROOT / "docs" / "report-top.png"))
            browser.close()


if __name__ == "__main__":
    main()
